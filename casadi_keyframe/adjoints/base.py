"""What a gradient route is, written once: the evaluation every route returns and the facts
the rest of the library asks it instead of branching on its name (the health guard, the
health report, a search's result, the command line's help)."""
from __future__ import annotations

import abc
import math
from dataclasses import dataclass

import numpy as np

from ..health import Growth
from ..state import Trajectory


@dataclass(frozen=True)
class Evaluation:
    """What one evaluation at a point computed, returned whole (nothing is left on the route
    to read afterwards):

    * ``value``: the objective there;
    * ``gradient``: its gradient by the route (None for a point judged without one);
    * ``trajectory``: the run it simulated, positions and velocities without records (None
      where the route ran none of its own at the point, as CasADi reverse mode on a model
      that decides nothing per step);
    * ``growth``: its watched backward pass's :class:`~casadi_keyframe.health.Growth` (None
      for a route without a backward loop of its own).
    """

    value: float
    gradient: np.ndarray | None
    trajectory: Trajectory | None = None
    growth: Growth | None = None


def bare(trajectory) -> Trajectory:
    """``trajectory``'s positions and velocities, its records (and what they hold) left
    behind."""
    return Trajectory(trajectory.x, trajectory.v, trajectory.dt)


class Route(abc.ABC):
    """A gradient route: an object passed as ``gradient=`` that owns its backward pass.

    **Evaluate** ``route.evaluate(problem, u)``: ``problem`` a
    :class:`~casadi_keyframe.problem.ControlProblem`, ``u`` its flat controls.
    **Returns** an :class:`Evaluation`: the objective at ``u``, its gradient by this route,
    the run it simulated and its backward growth.  ``route(problem, u)`` is the short form,
    ``(phi, grad)``.
    **Raises** :class:`~casadi_keyframe.health.GradientError` for a gradient it refuses (not
    finite, or a watched backward pass grown past ``bound``).

    **Facts** (class attributes): ``name`` (what ``gradient=`` and ``--gradient`` take),
    ``exact`` (the derivative of the scheme simulated, to round-off), ``bound`` (the backward
    growth past which it refuses; inf: refused only when not finite), ``help`` (its phrase in
    ``--gradient``'s help); and :meth:`limits`, :meth:`unreliable`, :meth:`likely_cause`,
    :meth:`unguarded`.
    """

    name: str = ""
    exact: bool = False
    bound: float = math.inf
    help: str = ""

    @abc.abstractmethod
    def evaluate(self, problem, u) -> Evaluation:
        """The :class:`Evaluation` of ``problem`` at controls ``u``."""

    def __call__(self, problem, u):
        """``(phi, dphi/du)`` of ``problem`` at controls ``u``."""
        found = self.evaluate(problem, u)
        return found.value, found.gradient

    def limits(self, model) -> list[str]:
        """Where this route is known not to apply on ``model`` (empty: none known)."""
        return []

    def unreliable(self, limits: list[str]) -> str:
        """The warning given once per model where :meth:`limits` named ``limits``."""
        return f"gradient '{self.name}' is unreliable on this model: {'; '.join(limits)}"

    def likely_cause(self, model) -> str:
        """Why this route's gradient was refused on ``model``, and the fix (a sentence)."""
        return "a non-finite value in the gradient. Fix: use --gradient adjoint (exact)"

    def unguarded(self) -> "Route":
        """This route with its guard off, so the health report measures an overflowing pass
        whole (a route without a guard of its own: itself)."""
        return self
