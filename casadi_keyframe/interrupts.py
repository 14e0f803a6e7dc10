"""SIGINT and SIGTERM as a remembered :class:`Interrupted` (a KeyboardInterrupt), and a
time limit as :class:`OutOfTime`, both raised at safe points.

A long solve stops the same way whichever signal stops it: the optimizers catch
KeyboardInterrupt and return their best point, and the command writes it and exits 130
(SIGINT) or 143 (SIGTERM).  Inside :func:`catching`, the first signal is raised at the next
safe point (:func:`check`: every objective evaluation, iteration, picture and animation
frame), not wherever the interpreter happens to be: raised inside a C extension calling
back into Python, an exception can be swallowed or become a SystemError (seen: CasADi's
``DM_from_array`` swallowing it, so a solve ran on to convergence; a SystemError from
``DM.__array__``; IPOPT ending with ``NonIpopt_Exception_Thrown``).  A second signal is
raised at once (and, should that raise be swallowed, again at the next safe point), except
inside :func:`deferred` (a file being moved into place), which raises it at its end.

Inside :func:`limited` the same safe points also raise :class:`OutOfTime` once the block's
time limit has passed, so one long evaluation, simulation or sweep stops near the limit
rather than at its end; whoever entered the block catches it and keeps its best point.
The loops of every stage (each simulated step and backward step, each evaluation, each
picture frame) call :func:`check`.
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading

NAMES = {signal.SIGINT: "SIGINT", signal.SIGTERM: "SIGTERM"}
_log: list[int] = []  # every signal the handler caught, in order
_state = {"depth": 0, "seen": 0, "pending": None, "held": 0}
_limits: list = []  # the time limits of the :func:`limited` blocks entered, innermost last

# a forked child (a shooting worker) is stopped by its parent, never by a limit of its own
os.register_at_fork(after_in_child=_limits.clear)


class Interrupted(KeyboardInterrupt):
    """Raised for a signal caught inside :func:`catching`; ``signum`` is the signal."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(NAMES.get(signum, f"signal {signum}"))
        self.signum = signum


def _handler(signum, frame):
    _log.append(signum)
    _state["seen"] += 1
    _state["pending"] = signum  # kept: code in CasADi may swallow the raise below
    if _state["seen"] > 1 and not _state["held"]:
        raise Interrupted(signum)


class OutOfTime(Exception):
    """Raised at a safe point inside :func:`limited` once its time limit has passed."""

    def __init__(self, limit=None):
        seconds = getattr(limit, "limit", None)
        super().__init__("time limit reached" if seconds is None
                         else f"time limit reached ({seconds:g} s)")
        self.limit = limit


def check() -> None:
    """A safe point: raise :class:`Interrupted` for a signal caught and not handled yet, or
    :class:`OutOfTime` inside a :func:`limited` block whose limit has passed."""
    signum = _state["pending"]
    if signum is not None and not _state["held"]:
        _state["pending"] = None
        raise Interrupted(signum)
    if _limits and _limits[-1].passed() and not _state["held"]:
        raise OutOfTime(_limits[-1])


@contextlib.contextmanager
def limited(limit):
    """Within the block :func:`check` raises :class:`OutOfTime` once ``limit`` (an object
    whose ``passed()`` says so, such as the optimizer's
    :class:`~casadi_keyframe.optimize.deadline.Deadline`; None: no limit) has passed; an
    enclosing block's limit does not reach inside it."""
    _limits.append(_Never() if limit is None else limit)
    try:
        yield limit
    finally:
        _limits.pop()


class _Never:
    """No limit (a :func:`limited` block that lifts an enclosing one)."""

    limit = None

    @staticmethod
    def passed() -> bool:
        return False


def handled() -> None:
    """Called where an interrupt has been acted on: later :func:`check` calls pass."""
    _state["pending"] = None


class Catch:
    """What :func:`catching` yields: ``signum``, the last signal since the block began."""

    def __init__(self):
        self.start = len(_log)

    @property
    def signum(self) -> int | None:
        return _log[-1] if len(_log) > self.start else None


@contextlib.contextmanager
def catching(*signums):
    """Within the block each of ``signums`` (default SIGINT and SIGTERM) raises
    :class:`Interrupted` (the first at the next :func:`check`, a second at once) and is
    logged; the previous handlers come back after.

    Only in the main thread (elsewhere signals cannot be handled: the block just runs); a
    signal the process ignores (SIGINT in a shell's background job) stays ignored."""
    catch = Catch()
    if threading.current_thread() is not threading.main_thread():
        yield catch
        return
    if _state["depth"] == 0:
        _state.update(seen=0, pending=None)
    previous = {}
    _state["depth"] += 1
    try:
        for s in signums or (signal.SIGINT, signal.SIGTERM):
            if signal.getsignal(s) is not signal.SIG_IGN:
                previous[s] = signal.signal(s, _handler)
        yield catch
    finally:
        _state["depth"] -= 1
        for s, old in previous.items():
            signal.signal(s, old)


@contextlib.contextmanager
def deferred():
    """A second signal arriving inside the block is raised at its end."""
    seen = _state["seen"]
    _state["held"] += 1
    try:
        yield
    finally:
        _state["held"] -= 1
    if not _state["held"] and _state["seen"] > max(seen, 1) and _state["pending"] is not None:
        signum, _state["pending"] = _state["pending"], None
        raise Interrupted(signum)
