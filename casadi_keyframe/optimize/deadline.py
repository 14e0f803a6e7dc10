"""The optimizer's one clock: :class:`Deadline`, made once per call and handed to every stage,
round and method, and :func:`now`, the only clock the optimizer reads (a stage's seconds, an
evaluation's, the history's).

A method asks :meth:`Deadline.passed` between its steps and stops there; a library that
takes a wall-time budget of its own (IPOPT's ``max_wall_time``) is given
:meth:`Deadline.left`.  A part of a call with a limit of its own (the finish's searches
called alone) makes its deadline with :meth:`Deadline.start`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

LEAST = 1e-3  # s: the budget a library is given once the deadline has passed (0 means none)


def now() -> float:
    """The optimizer's clock (``time.perf_counter``), in seconds: for differences only."""
    return time.perf_counter()


@dataclass(frozen=True)
class Deadline:
    """A call's wall clock: it ``started`` (:func:`now`) and may run ``limit`` seconds (None:
    no limit)."""

    started: float
    limit: float | None = None

    @classmethod
    def start(cls, limit: float | None = None) -> "Deadline":
        """A deadline ``limit`` seconds from now (None: none)."""
        return cls(now(), limit)

    def passed(self) -> bool:
        """Whether the limit is reached (never without one)."""
        return self.limit is not None and now() - self.started >= self.limit

    def left(self) -> float | None:
        """Seconds left (at least :data:`LEAST`), None without a limit."""
        if self.limit is None:
            return None
        return max(self.limit - (now() - self.started), LEAST)

    def elapsed(self) -> float:
        """Seconds since it started."""
        return now() - self.started
