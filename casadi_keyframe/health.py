r"""Gradient health, the part every evaluation pays for: the backward pass watched, and a
gradient refused when it cannot be right.  A route (:mod:`casadi_keyframe.adjoints`) brings
its own facts: its bound, its known limits, the likely cause of a refusal and its fix.

**Growth.**  The backward loop (eq. 5) carries the adjoint ``a_n = (a_x, a_v)`` from the last
frame to the first; its growth at frame n is ``|a_n| / max_{m > n} |s_m|``, ``s_m`` the
objective's gradient at frame m, in the norm ``|(dt a_x, a_v)|`` (a pure number at any dt).

**The bound.**  Past its route's ``bound`` or at a non-finite value a watched pass raises
:class:`GradientError` at once, naming the route, the frame, the likely cause and the fix:
the optimizer treats it as a failed simulation, so no overflowed gradient reaches L-BFGS-B
or IPOPT.  A route without a backward loop of its own is refused only for a non-finite
gradient.  The full report at a point is :mod:`casadi_keyframe.studies.health_report`.
"""
from __future__ import annotations

import math
import warnings
import weakref
from dataclasses import dataclass

import numpy as np

from .state import SimulationError

GROWTH_BOUND = 1e8  # the bound an approximate route's watched backward pass is held to


def past_bound(growth: float, bound: float) -> bool:
    """Whether a backward pass's ``growth`` fails its evaluation: not finite, or past
    ``bound``."""
    return not (math.isfinite(growth) and growth <= bound)


class GradientError(SimulationError):
    """A gradient route's backward pass overflowed or grew past its bound: the
    evaluation fails (the simulation itself did not).  ``route`` is the route's name, ``step``
    the frame where it was detected, ``growth`` the growth reached (inf if not finite)."""

    def __init__(self, message: str, step: int, route: str, growth: float):
        super().__init__(message, step)
        self.route, self.growth = route, growth


class GradientRouteWarning(UserWarning):
    """A gradient route is used where it is known to be unreliable (its ``limits``)."""


@dataclass(frozen=True)
class Growth:
    """What a watched backward pass saw: ``growth`` (largest ``|a_n| / max_{m>n} |s_m|``),
    ``frame`` where it was largest, ``fastest`` (the largest growth of the adjoint in one
    backward step) and ``fastest_step`` (that step's index), ``steps`` in the pass."""

    growth: float
    frame: int
    fastest: float
    fastest_step: int
    steps: int


class BackwardWatch:
    """Watches one backward pass (:func:`~casadi_keyframe.simulate.backward` calls it) of
    ``route`` (a :class:`~casadi_keyframe.adjoints.Route`) on ``problem``: :meth:`start` with
    every frame's objective gradient, then :meth:`step` after each backward step.  With
    ``guard`` it raises :class:`GradientError` past ``bound`` (default: the route's) or at a
    non-finite adjoint; without, it only records (the health report wants the growth of a
    route that overflows).  Two dot products per step, in Python floats (no floating-point
    state to save and restore)."""

    def __init__(self, route, problem, *, bound: float | None = None, guard: bool = True):
        self.route, self.problem, self.guard = route, problem, guard
        self.bound = route.bound if bound is None else bound
        self.dt2, self.steps = problem.dt ** 2, problem.steps
        self.sources = None  # |s_m| of every frame
        self.source = 0.0  # the largest |s_m| fed in after the current frame
        self.previous = 0.0  # |a_{n+1}| as the last step received it
        self.growth, self.frame = 0.0, problem.steps
        self.fastest, self.fastest_step = 0.0, problem.steps - 1

    def _norm(self, x, v) -> float:
        return math.sqrt(self.dt2 * float(np.vdot(x, x)) + float(np.vdot(v, v)))

    def start(self, gx, gv) -> None:
        """Every frame's objective gradient ``(gx, gv)``, ``(steps + 1, n, dim)`` each."""
        frames = len(gx)
        x, v = np.reshape(gx, (frames, -1)), np.reshape(gv, (frames, -1))
        self.sources = np.sqrt(self.dt2 * np.einsum("fk,fk->f", x, x)
                               + np.einsum("fk,fk->f", v, v)).tolist()
        self.source = self.previous = self.sources[-1]

    def step(self, n: int, pulled, total) -> None:
        """After backward step n: ``pulled`` the cotangent pulled back to frame n, ``total``
        the same plus frame n's own objective gradient (what step n - 1 receives)."""
        size = self._norm(pulled.x, pulled.v)
        if self.previous > 0 and size / self.previous > self.fastest:
            self.fastest, self.fastest_step = size / self.previous, n
        if not math.isfinite(size):
            self.growth, self.frame = math.inf, n
        elif self.source > 0 and size / self.source > self.growth:
            self.growth, self.frame = size / self.source, n
        self.source = max(self.source, self.sources[n])
        self.previous = self._norm(total.x, total.v)
        if self.guard and past_bound(self.growth, self.bound):
            raise GradientError(self.message(), n, self.route.name, self.growth)

    def result(self) -> Growth:
        return Growth(float(self.growth), int(self.frame), float(self.fastest),
                      int(self.fastest_step), int(self.steps))

    def message(self) -> str:
        """The refusal (:func:`refusal`)."""
        return refusal(self.route, self.problem, self.result(), self.bound)


def refusal(route, problem, growth: Growth, bound: float | None = None) -> str:
    """Why ``route``'s gradient is refused: where its backward pass went past ``bound``
    (default: the route's), how far, the likely cause and the fix."""
    bound = route.bound if bound is None else bound
    what = ("overflowed (a non-finite adjoint)" if not np.isfinite(growth.growth) else
            f"grew {growth.growth:.3g}-fold (bound {bound:.0e})")
    return (f"gradient '{route.name}' refused: its backward pass {what} by frame "
            f"{growth.frame} of {growth.steps}, growing fastest at step {growth.fastest_step} "
            f"(x{growth.fastest:.3g} in one step); the simulation itself is fine. Likely "
            f"cause: {route.likely_cause(problem.model)}")


_WARNED: "weakref.WeakSet" = weakref.WeakSet()


def warn_route_limits(route, model) -> None:
    """Warn once per model (:class:`GradientRouteWarning`) if ``route`` is known not to
    apply to it (its ``limits``)."""
    try:
        if model in _WARNED:
            return
        _WARNED.add(model)
    except TypeError:  # a model that cannot be weakly referenced is checked every time
        pass
    limits = route.limits(model)
    if limits:
        warnings.warn(route.unreliable(limits), GradientRouteWarning, stacklevel=3)


def check_finite(route, grad, problem) -> None:
    """Refuse ``route``'s gradient with a NaN or an infinity (:class:`GradientError`)."""
    if not np.all(np.isfinite(grad)):
        raise GradientError(f"gradient '{route.name}' refused: it holds non-finite values. "
                            f"Likely cause: {route.likely_cause(problem.model)}",
                            problem.steps, route.name, np.inf)


class GrowthLog:
    """The growth of every evaluation of a search (the optimizer's cheap health record):
    ``last`` (of the last evaluation, None for a route that runs no watched pass), the
    ``largest`` seen and how many evaluations were ``refused`` (:class:`GradientError`)."""

    def __init__(self):
        self.last, self.largest, self.refused = None, None, 0

    def seen(self, growth: Growth | None) -> None:
        """After an evaluation whose backward pass grew by ``growth`` (None: it watched
        none)."""
        self.last = None if growth is None else growth.growth
        if self.last is not None:
            self.largest = self.last if self.largest is None else max(self.largest, self.last)

    def failed(self, err) -> None:
        """After an evaluation that failed with ``err``."""
        self.last = None
        if isinstance(err, GradientError):
            self.refused += 1
            self.largest = err.growth if self.largest is None else max(self.largest,
                                                                       err.growth)

    def stage_fields(self) -> dict:
        """The optional :class:`~casadi_keyframe.optimize.result.Stage` keys."""
        out = {"gradient_refused": self.refused}
        if self.largest is not None:
            out["gradient_growth"] = float(self.largest)
        return out
