r"""Gradient health, the part every evaluation pays for: the backward pass watched, and a
gradient refused when it cannot be right.

**Growth.**  The backward loop (eq. 5) carries the adjoint ``a_n = (a_x, a_v)`` from the last
frame to the first, adding each frame's objective gradient ``s_n = dphi/ds_n`` on the way.
Its *growth* at frame n is ``|a_n| / max_{m > n} |s_m|``: how much larger the adjoint pulled
back to frame n is than anything fed into it after n.  Norms are ``|(dt a_x, a_v)|``, both
parts in units of phi per m/s, so the ratio is a pure number for any time step.  A pass's
growth is the largest over its frames; the step where one backward step grew the adjoint
most (its *fastest* step) says where it happens.  The exact adjoint of a stable simulation
grows like the motion's sensitivity (tens to thousands on the shipped problems); the
paper's swapped adjoint near curved colliders grows by orders of magnitude per step, up to
overflow, while the simulation itself is fine.

**The bound.**  Past its route's bound (:func:`growth_bound`) or at a non-finite value a
watched pass raises :class:`GradientError` at once, naming the route, the frame, the likely
cause and the fix: the optimizer (:class:`~casadi_keyframe.optimize.evaluator.Evaluator`)
treats it as a failed simulation, so no overflowed gradient ever reaches L-BFGS-B or IPOPT.
An approximate route is held to :data:`GROWTH_BOUND` (1e8): past it the swapped adjoint has
left the exact one behind (it diverges near curved colliders).  An exact route is the
derivative of the simulated map however sensitive that map is, and the route users are sent
to when another is refused, so it is refused only when not finite; its growth is on record
(history, ``summary.json``, ``gradcheck``'s verdict).  A growth is a ratio to what the
objective fed in: at a start that already hits its keyframes to round-off, a landing's large
guessed forces make it enormous while the gradient itself is tiny.  Routes that run no
backward loop of their own (CasADi's reverse mode, finite differences) are refused only
for a non-finite gradient.

**Known limits.**  :func:`route_limits` names where a route is known not to apply (the
swapped route under penalty springs on curved bodies, or with self-contact): the swapped
strategy warns once per model (:class:`GradientRouteWarning`).

The full report at a point (dot-product test, finite differences, linearity radius, the
exact route for comparison) is :mod:`casadi_keyframe.health_report`.
"""
from __future__ import annotations

import math
import warnings
import weakref
from dataclasses import dataclass

import numpy as np

from .state import SimulationError

GROWTH_BOUND = 1e8  # an approximate route's backward pass past this fails the evaluation
APPROXIMATE_ROUTES = ("swapped",)


def growth_bound(route: str) -> float:
    """The growth past which ``route``'s watched backward pass fails the evaluation (an exact
    route's: none, only a non-finite adjoint)."""
    return GROWTH_BOUND if route in APPROXIMATE_ROUTES else math.inf


def past_bound(growth: float, bound: float) -> bool:
    """Whether a backward pass's ``growth`` fails its evaluation: not finite, or past
    ``bound``."""
    return not (math.isfinite(growth) and growth <= bound)


class GradientError(SimulationError):
    """A gradient route's backward pass overflowed or grew past its bound: the
    evaluation fails (the simulation itself did not).  ``route`` names the route, ``step``
    the frame where it was detected, ``growth`` the growth reached (inf if not finite)."""

    def __init__(self, message: str, step: int, route: str, growth: float):
        super().__init__(message, step)
        self.route, self.growth = route, growth


class GradientRouteWarning(UserWarning):
    """A gradient route is used where it is known to be unreliable (:func:`route_limits`)."""


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

    def as_dict(self) -> dict:
        return {"growth": self.growth, "frame": self.frame, "fastest": self.fastest,
                "fastest_step": self.fastest_step}


class BackwardWatch:
    """Watches one backward pass (:func:`~casadi_keyframe.simulate.backward` calls it) for the
    route ``route`` of ``problem``: :meth:`start` with every frame's objective gradient, then
    :meth:`step` after each backward step.  With ``guard`` it raises :class:`GradientError`
    past ``bound`` or at a non-finite adjoint; without, it only records (the health report
    wants the growth of a route that overflows).  Two dot products per step, in Python
    floats (no floating-point state to save and restore)."""

    def __init__(self, route: str, problem, *, bound: float | None = None,
                 guard: bool = True):
        self.route, self.problem, self.guard = route, problem, guard
        self.bound = growth_bound(route) if bound is None else bound
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
            raise GradientError(self.message(), n, self.route, self.growth)

    def result(self) -> Growth:
        return Growth(float(self.growth), int(self.frame), float(self.fastest),
                      int(self.fastest_step), int(self.steps))

    def message(self) -> str:
        """The refusal (:func:`refusal`)."""
        return refusal(self.route, self.problem, self.result(), self.bound)


def refusal(route: str, problem, growth: Growth, bound: float | None = None) -> str:
    """Why ``route``'s gradient is refused: where its backward pass went past ``bound``, how
    far, the likely cause and the fix."""
    bound = growth_bound(route) if bound is None else bound
    what = ("overflowed (a non-finite adjoint)" if not np.isfinite(growth.growth) else
            f"grew {growth.growth:.3g}-fold (bound {bound:.0e})")
    return (f"gradient '{route}' refused: its backward pass {what} by frame {growth.frame} "
            f"of {growth.steps}, growing fastest at step {growth.fastest_step} "
            f"(x{growth.fastest:.3g} in one step); the simulation itself is fine. Likely "
            f"cause: {likely_cause(route, problem.model)}")


def likely_cause(route: str, model) -> str:
    """Why ``route``'s backward pass grows on ``model``, and what to do (a sentence)."""
    if route == "swapped":
        limits = route_limits(route, model)
        where = ("; here: " + "; ".join(limits)) if limits else ""
        return ("the paper's swapped adjoint updates with the full force Jacobian, whose "
                "destabilising parts (contact curvature and contact damping on curved "
                "bodies, compressed springs) its backward recurrence amplifies every step"
                f"{where}. Fix: use --gradient adjoint (gradient='adjoint', exact, same cost); "
                "a reduced dt does not help (the growth compounds per step)")
    if route == "adjoint":
        return ("the motion itself is this sensitive (a long horizon through many contact "
                "switches, springs collapsed to almost no length, a simulation near blowing "
                "up): the exact gradient's linear model holds only for tiny steps. Fix: "
                "shorten the horizon or the window optimized, start from a better guess, or "
                "reduce the forces")
    return "a non-finite value in the gradient. Fix: use --gradient adjoint (exact)"


def route_limits(route: str, model) -> list[str]:
    """Where ``route`` is known not to apply on ``model`` (an empty list: none known): the
    swapped route under penalty springs on curved bodies (sphere, capsule), whose curvature
    and damping terms make its backward pass grow without bound, and with self-contact."""
    if route != "swapped":
        return []
    from .models.penalty import BodyPenalty, SelfPenalty

    families = getattr(model, "families", ())
    curved = sorted({f.body.kind for f in families
                     if isinstance(f, BodyPenalty) and f.body.kind != "plane"})
    out = []
    if curved:
        out.append(f"penalty contact on curved bodies ({', '.join(curved)}s) can make it "
                   "overflow")
    if any(isinstance(f, SelfPenalty) for f in families):
        out.append("self-contact makes it inaccurate")
    return out


_WARNED: "weakref.WeakSet" = weakref.WeakSet()


def warn_route_limits(route: str, model) -> None:
    """Warn once per model (:class:`GradientRouteWarning`) if ``route`` is known not to
    apply to it (:func:`route_limits`)."""
    try:
        if model in _WARNED:
            return
        _WARNED.add(model)
    except TypeError:  # a model that cannot be weakly referenced is checked every time
        pass
    limits = route_limits(route, model)
    if limits:
        warnings.warn(f"gradient '{route}' is unreliable on this model: {'; '.join(limits)} "
                      "(see 'casadi-keyframe study swap-validity'); the evaluation fails if "
                      "its backward pass overflows. Use gradient='adjoint' (exact, same cost)",
                      GradientRouteWarning, stacklevel=3)


def check_finite(route: str, grad, problem) -> None:
    """Refuse a gradient with a NaN or an infinity (:class:`GradientError`)."""
    if not np.all(np.isfinite(grad)):
        raise GradientError(f"gradient '{route}' refused: it holds non-finite values. Likely "
                            f"cause: {likely_cause(route, problem.model)}", problem.steps,
                            route, np.inf)


class GrowthLog:
    """The growth of every evaluation of a search (the optimizer's cheap health record):
    ``last`` (of the last evaluation, None for a route that runs no watched pass), the
    ``largest`` seen and how many evaluations were ``refused`` (:class:`GradientError`)."""

    def __init__(self):
        self.last, self.largest, self.refused = None, None, 0

    def seen(self, strategy) -> None:
        """After an evaluation by ``strategy``: read the growth it recorded."""
        growth = getattr(strategy, "growth", None)
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
