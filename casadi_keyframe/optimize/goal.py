"""The animator's goal: every keyframe within its tolerance, the cloth whole and above the
bodies it touches (:class:`~casadi_keyframe.objectives.tolerances.PhysicalLimits`).

Each keyframe term declares when it counts as met (``StateKeyframe(..., tolerance=...)``,
``RegionTarget(..., fill=...)``, with defaults; see :mod:`casadi_keyframe.objectives.tolerances`).
:func:`verdict` checks a trajectory against them.  A search uses it twice: to stop as soon
as the goal is met (``solve(..., stop="goal")``), and to say truthfully how it ended
(:func:`~.outcome.judge`): a search whose method stopped is "converged" only when the goal
is met, and a message names every keyframe still missed and by how much.
"""
from __future__ import annotations

from dataclasses import dataclass

STOPS = ("goal", "method")


@dataclass(frozen=True)
class Verdict:
    """Whether a trajectory meets a problem's goal.

    * ``met``: every keyframe with a tolerance is within it and the motion within the
      problem's physical limits (False when no keyframe has a tolerance);
    * ``misses``: one phrase per keyframe still missed, naming each miss and its tolerance,
      then one per physical limit broken (torn, sunk);
    * ``checked``: how many keyframe terms declare a tolerance (0: the problem has no goal,
      and ``met`` says nothing); ``physical``: whether physical limits were checked.
    """

    met: bool
    misses: tuple
    checked: int
    physical: bool = False

    def describe(self) -> str:
        """``"every keyframe within its tolerance"`` or ``"still missed: ..."``."""
        if not self.checked:
            return "no keyframe declares a tolerance"
        if self.met:
            return "every keyframe within its tolerance" + (
                ", the motion within its physical limits" if self.physical else "")
        return "still missed: " + "; ".join(self.misses)


def has_goal(problem) -> bool:
    """Whether any keyframe term of ``problem`` declares a tolerance."""
    return any(t.has_tolerance for t in problem.objective_terms.state_terms)


def verdict(problem, trajectory) -> Verdict:
    """The :class:`Verdict` of ``problem``'s keyframe terms and physical limits on
    ``trajectory``."""
    terms = [t for t in problem.objective_terms.state_terms if t.has_tolerance]
    misses = tuple(m for t in terms if (m := t.shortfall(trajectory)) is not None)
    broken = tuple(problem.physical_shortfall(trajectory))
    return Verdict(met=bool(terms) and not misses and not broken, misses=misses + broken,
                   checked=len(terms), physical=getattr(problem, "limits", None) is not None)


def check_stop(stop, problem) -> str:
    """``stop`` checked (ValueError naming the choices): ``"goal"`` (stop once every
    keyframe is within its tolerance) or ``"method"`` (run the method to its own test);
    None means ``"goal"`` where the problem declares tolerances, else ``"method"``."""
    if stop is None:
        return "goal" if has_goal(problem) else "method"
    if stop not in STOPS:
        raise ValueError(f"stop must be 'goal' (stop once every keyframe is within its "
                         f"tolerance) or 'method' (run the method to its own test), got "
                         f"{stop!r}")
    return stop


class GoalReached(Exception):
    """Raised at an iteration where the goal is met, to stop the search (``stop="goal"``)."""

    def __init__(self, verdict: Verdict, iteration: int):
        super().__init__(verdict.describe())
        self.verdict, self.iteration = verdict, iteration
