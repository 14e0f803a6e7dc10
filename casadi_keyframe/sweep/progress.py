"""The sweep's progress on the terminal: one line per finished point, and on a terminal a
status line kept at the bottom (points done, failed, running, waiting; time left); away
from a terminal (a log) that status is a line of its own whenever
:data:`~casadi_keyframe.progress.EVERY` seconds pass without one, so a sweep of long points
never goes silent."""
from __future__ import annotations

import sys
import time

from ..progress import EVERY, format_seconds
from .tasks import ERROR, failed


class Progress:
    """Counts finished points and shows them on ``stream`` (default stderr); ``total`` is
    the number of points this run solves, ``skipped`` those ``--resume`` found complete."""

    def __init__(self, total: int, *, skipped: int = 0, stream=None, enabled: bool = True):
        self.total, self.skipped, self.enabled = total, skipped, enabled
        self.stream = stream or sys.stderr
        self.live = enabled and getattr(self.stream, "isatty", lambda: False)()
        self.done = self.failed = 0
        self.seconds: list[float] = []
        self.started = self.last = time.monotonic()
        if enabled:
            extra = f" ({skipped} already complete, skipped)" if skipped else ""
            self._line(f"sweep: {total} point{'s' * (total != 1)} to solve{extra}")

    def point(self, row: dict, *, running: int = 0, slots: int = 1) -> None:
        """A point finished (``row`` its table line); redraw the status line."""
        self.done += 1
        self.failed += failed(row)
        self.seconds.append(float(row.get("seconds") or 0.0))
        if self.enabled:
            self._line(f"  [{self.done}/{self.total}] {row.get('label', row['point'])}: "
                       + describe(row))
            self.status(running, slots)

    def note(self, text: str) -> None:
        """A line shown even without the progress display (a worker that died)."""
        self._line(text)

    def status(self, running: int, slots: int) -> None:
        """Rewrite the status line on a terminal; elsewhere write it as a line once
        :data:`~casadi_keyframe.progress.EVERY` seconds have passed without one."""
        if self.live:
            self.stream.write("\r\033[K" + self.summary(running, slots))
            self.stream.flush()
        elif self.enabled and time.monotonic() - self.last >= EVERY:
            self._line(self.summary(running, slots))

    def summary(self, running: int, slots: int) -> str:
        """``"sweep: 5/16 done (1 failed), 2 running, 9 waiting; about 3 min left"``."""
        waiting = max(self.total - self.done - running, 0)
        text = (f"sweep: {self.done}/{self.total} done"
                + (f" ({self.failed} failed)" if self.failed else "")
                + f", {running} running, {waiting} waiting")
        left = self.eta(slots)
        return text + (f"; about {format_seconds(left)} left" if left is not None else "")

    def eta(self, slots: int) -> float | None:
        """Seconds left: the points not finished times the mean seconds of a finished one,
        shared among ``slots`` workers; None before the first point finishes."""
        if not self.seconds:
            return None
        remaining = self.total - self.done
        return remaining * (sum(self.seconds) / len(self.seconds)) / max(slots, 1)

    def close(self) -> None:
        if self.live:
            self.stream.write("\r\033[K")
        if self.enabled:
            self._line(f"sweep: {self.done}/{self.total} finished"
                       + (f", {self.failed} failed" if self.failed else "")
                       + f" in {format_seconds(time.monotonic() - self.started)}")

    def _line(self, text: str) -> None:
        if self.live:
            self.stream.write("\r\033[K")
        self.stream.write(text + "\n")
        self.stream.flush()
        self.last = time.monotonic()


def describe(row: dict) -> str:
    """``"converged, objective 0.0123, 15 iterations (12.3 s)"`` or the failure's reason."""
    status = row.get("status", "?")
    seconds = f" ({float(row.get('seconds') or 0):.1f} s)"
    if status == ERROR:
        return f"FAILED: {row.get('reason', '')}{seconds}"
    if "objective" in row:
        return (f"{status}, objective {row['objective']:.6g}, {row.get('iterations', '?')} "
                f"iterations{seconds}")
    return status + seconds
