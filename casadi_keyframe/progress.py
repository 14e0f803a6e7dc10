"""What a long run is doing, said often enough that it never looks hung.

Work says what it does as a stack of tasks (:func:`task`: a stage, an iteration, a
simulation of many steps, a picture's frames), each with how much is done of how much
(:func:`advance`); the loops that advance them are the same that check for a signal and the
time limit (:func:`~casadi_keyframe.interrupts.check`).  A :class:`Reporter` made by
:func:`reporting` (the command line's runs, a ``solve`` that is not quiet) shows the stack:
on a terminal as one status line redrawn in place (at least every second), elsewhere (a log,
a pipe) as a line whenever :data:`EVERY` seconds have passed without one, each with the time
spent and, where the work's size is known, the time left.  A stage's end is a line of its
own (:func:`say`), kept under ``quiet``, which drops the rest.  Without a reporter every
call here does nothing but count.
"""
from __future__ import annotations

import contextlib
import os
import sys
import threading
import time

EVERY = 8.0  # s: the longest a reporter stays silent away from a terminal
REDRAW = 0.25  # s: the least time between two redraws of a terminal's status line

_tasks: list = []  # the tasks entered, outermost first
_reporters: list = []  # the reporters entered, innermost last


def _forked() -> None:
    """In a forked child (a shooting worker): no reporter, no tasks (the parent shows the
    work, and a lock its thread held would never be let go here)."""
    _reporters.clear()
    _tasks.clear()


os.register_at_fork(after_in_child=_forked)


class Task:
    """One thing being done: ``label``, ``done`` of ``total`` ``unit`` (None: unknown),
    since ``started``; ``facts`` a short text of its latest figures; ``limit`` (an object
    with ``left()``, such as a Deadline) bounds its time left; ``exact`` says whether
    ``total`` is the work to do (steps, frames: "about" so much left) or a bound on it
    (iterations up to a maximum: "at most")."""

    def __init__(self, label: str, total=None, unit: str = "", *, limit=None,
                 exact: bool = True):
        self.label, self.total, self.unit, self.limit = label, total, unit, limit
        self.exact, self.done, self.facts = exact, 0, ""
        self.started = time.monotonic()

    def left(self) -> tuple[str, float] | None:
        """``("about" or "at most", seconds)`` left, where it can be known."""
        found = None
        if self.total and self.done:
            rate = (time.monotonic() - self.started) / self.done
            found = ("about" if self.exact else "at most", rate * max(self.total - self.done, 0))
        if self.limit is not None and self.limit.left() is not None:
            bound = float(self.limit.left())
            if found is None or bound < found[1]:
                found = ("at most", bound)
        return found

    def describe(self) -> str:
        count = ""
        if self.total:
            count = f" {self.done}/{self.total}{' ' + self.unit if self.unit else ''}"
        elif self.done:
            count = f" {self.done}{' ' + self.unit if self.unit else ''}"
        return f"{self.label}{count}{', ' + self.facts if self.facts else ''}"


@contextlib.contextmanager
def task(label: str, total=None, unit: str = "", *, limit=None, exact: bool = True):
    """A task on the stack for the block (see :class:`Task`); yields it."""
    entered = Task(label, total, unit, limit=limit, exact=exact)
    _tasks.append(entered)
    try:
        yield entered
    finally:
        _tasks.remove(entered)
        if _reporters:
            _reporters[-1].tick() if _tasks else _reporters[-1].clear()


def advance(count: int = 1, facts: str | None = None) -> None:
    """The innermost task did ``count`` more (``facts``: its latest figures)."""
    if _tasks:
        top = _tasks[-1]
        top.done += count
        if facts is not None:
            top.facts = facts
        if _reporters:
            _reporters[-1].tick()


def say(text: str, *, stage: bool = False) -> None:
    """A line of its own (``stage``: a stage's end, kept under ``quiet``); with no
    reporter, nothing."""
    if _reporters:
        _reporters[-1].line(text, stage=stage)


def note(text: str) -> None:
    """``note: text`` on stderr, shown always (under ``quiet`` too, and with no reporter):
    what the run changed or found in its input (quads split, a window shortened)."""
    if _reporters:
        _reporters[-1].line(f"note: {text}", stage=True)
    else:
        print(f"note: {text}", file=sys.stderr)


def status() -> str:
    """The stack as one line: ``"cape_blend: finish (lowering effort) 2/10 steps >
    simulating 45/60 steps; 3 min 20 s in, about 1 min left"``."""
    tasks = list(_tasks)  # the work's thread may change the stack meanwhile
    if not tasks:
        return ""
    text = " > ".join(t.describe() for t in tasks)
    spent = format_seconds(time.monotonic() - tasks[0].started)
    lefts = [t.left() for t in tasks]
    known = [found for found in lefts if found is not None]
    left = f", {known[0][0]} {format_seconds(known[0][1])} left" if known else ""
    return f"{text}; {spent} in{left}"


def active() -> bool:
    """Whether a reporter shows the work (something is watching)."""
    return bool(_reporters)


class Reporter:
    """Shows :func:`status` on ``stream``: redrawn in place on a terminal (``live``), else
    a line after :data:`EVERY` (``every``) seconds of silence; ``quiet``: stage lines alone.
    A thread keeps it talking while the work is inside one long call."""

    def __init__(self, stream=None, *, quiet: bool = False, every: float = EVERY,
                 live: bool | None = None):
        self.stream = stream or sys.stderr
        self.quiet, self.every = quiet, every
        self.live = (not quiet and getattr(self.stream, "isatty", lambda: False)()
                     if live is None else live)
        self.lock = threading.Lock()
        self.last = self.drawn = time.monotonic()
        self.shown = False  # a status line is on the terminal's last line
        self.stopped = threading.Event()
        self.thread = None

    def start(self) -> "Reporter":
        if not self.quiet:
            self.thread = threading.Thread(target=self._beat, name="progress", daemon=True)
            self.thread.start()
        return self

    def stop(self) -> None:
        self.stopped.set()
        if self.thread is not None:
            self.thread.join(timeout=2)
        with self.lock:
            self._clear()

    def line(self, text: str, *, stage: bool = False) -> None:
        if self.quiet and not stage:
            return
        with self.lock:
            self._clear()
            self._write(text + "\n")

    def clear(self) -> None:
        """Take the terminal's status line away (the work it showed has ended: what is
        printed next starts on a clean line)."""
        with self.lock:
            self._clear()

    def tick(self) -> None:
        """The stack changed: redraw the terminal's status line (at most every
        :data:`REDRAW` seconds)."""
        if self.live and time.monotonic() - self.drawn >= REDRAW:
            with self.lock:
                self._draw()

    def _beat(self) -> None:
        while not self.stopped.wait(min(1.0, self.every / 4)):
            with self.lock:
                if self.live:
                    self._draw()
                elif time.monotonic() - self.last >= self.every and _tasks:
                    self._write(status() + "\n")

    def _draw(self) -> None:
        text = status()
        if not text:
            return
        width = _columns(self.stream) - 1
        self._write("\r\033[K" + (text if len(text) <= width else text[:width - 1] + "\u2026"))
        self.shown, self.drawn = True, time.monotonic()

    def _clear(self) -> None:
        if self.shown:
            self._write("\r\033[K")
            self.shown = False

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # a closed or broken stream: the work goes on
            pass
        self.last = time.monotonic()


@contextlib.contextmanager
def reporting(quiet: bool = False, *, stream=None, every: float = EVERY):
    """A :class:`Reporter` for the block (an enclosing one is used as it is)."""
    if _reporters:
        yield _reporters[-1]
        return
    reporter = Reporter(stream, quiet=quiet, every=every).start()
    _reporters.append(reporter)
    try:
        yield reporter
    finally:
        _reporters.remove(reporter)
        reporter.stop()


def _columns(stream) -> int:
    """The terminal's width (100 where it says none)."""
    try:
        return os.get_terminal_size(stream.fileno()).columns or 100
    except (AttributeError, OSError, ValueError):
        return 100


def format_seconds(seconds: float) -> str:
    """``"45 s"``, ``"3 min 20 s"``, ``"1 h 5 min"``."""
    seconds = max(float(seconds), 0.0)
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60)} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60)} min"
