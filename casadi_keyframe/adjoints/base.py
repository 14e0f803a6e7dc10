"""What a gradient route is, written once: the call every route answers and the facts the
rest of the library asks it instead of branching on its name (the health guard, the health
report, a search's result, the command line's help)."""
from __future__ import annotations

import abc
import math


class Route(abc.ABC):
    """A gradient route: an object passed as ``gradient=`` that owns its backward pass.

    **Call** ``route(problem, u)``: ``problem`` a
    :class:`~casadi_keyframe.problem.ControlProblem`, ``u`` its flat controls.
    **Returns** ``(phi, grad)``: the objective at ``u`` and its gradient by this route.
    **Raises** :class:`~casadi_keyframe.health.GradientError` for a gradient it refuses (not
    finite, or a watched backward pass grown past ``bound``).

    **Facts** (class attributes): ``name`` (what ``gradient=`` and ``--gradient`` take),
    ``exact`` (the derivative of the scheme simulated, to round-off), ``bound`` (the backward
    growth past which it refuses; inf: refused only when not finite), ``help`` (its phrase in
    ``--gradient``'s help), ``growth`` (the last watched pass's
    :class:`~casadi_keyframe.health.Growth`; None for a route without a backward loop of its
    own); and :meth:`limits`, :meth:`unreliable`, :meth:`likely_cause`, :meth:`unguarded`.
    """

    name: str = ""
    exact: bool = False
    bound: float = math.inf
    help: str = ""
    growth = None

    @abc.abstractmethod
    def __call__(self, problem, u):
        """``(phi, dphi/du)`` of ``problem`` at controls ``u``."""

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
