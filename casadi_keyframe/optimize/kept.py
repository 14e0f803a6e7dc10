"""Which of two points is better, and the best one kept.

:class:`Standing` is the one ranking of points: the goal met first (every keyframe within
its tolerance, the motion within its physical limits), then the lower objective.  The
evaluator's best point, the kept point, the checkpoint on disk and the finish's steps are all
ranked by it.  :class:`Kept` is the best point a solve has seen on its final problem: what it
returns when its stages (coarser meshes, a homotopy, multiple shooting, rounds, the finish, a
resumed run's start) end worse than an earlier point, so that no solve returns a point worse
than its start; :func:`conclude` makes the :class:`~.result.Result` at it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..state import SimulationError
from .goal import verdict
from .outcome import CONVERGED, FAILED
from .result import Result, assemble, stage_record


@dataclass(frozen=True)
class Standing:
    """Where a point stands: whether it ``met`` the goal, then its ``objective`` (lower is
    better); a solve that ranks the points meeting the goal by their control cost (least
    effort under the goal: the transcription) gives their ``effort`` too, and those points
    are then ranked by it."""

    met: bool
    objective: float
    effort: float | None = None

    def _key(self) -> tuple:
        value = self.effort if self.met and self.effort is not None else self.objective
        return (bool(self.met), -float(value))

    def beats(self, other: "Standing | None") -> bool:
        """Strictly better than ``other`` (anything beats None)."""
        return other is None or self._key() > other._key()

    def at_least(self, other: "Standing | None") -> bool:
        """At least as good as ``other`` (a tie counts)."""
        return other is None or self._key() >= other._key()


class Kept:
    """The best point offered so far on ``problem``, judged by ``goal`` (its terms and
    limits: met first, then, ``by_objective``, the lower objective on its targets; a later
    point wins a tie); each better point is also offered to the ``checkpoint`` (or None).
    Rounds of hard keyframes rank by the goal alone: each round trades objective for a
    smaller miss on purpose."""

    def __init__(self, problem, goal, checkpoint, *, by_objective: bool = True):
        self.problem, self.goal, self.checkpoint = problem, goal, checkpoint
        self.by_objective = by_objective
        self.u = self.trajectory = self.standing = self.objective = None
        self.where = ""

    def judge(self, u, trajectory) -> Standing:
        """The standing of controls ``u`` whose run is ``trajectory``, on the goal's targets."""
        fun = (self.goal.state_cost(trajectory, gradient=False)[0]
               + self.goal.control_cost(u)[0])
        return Standing(verdict(self.goal, trajectory).met, float(fun))

    def _ranked(self, standing: Standing) -> Standing:
        return standing if self.by_objective else Standing(standing.met, 0.0)

    def beats(self, u, trajectory) -> bool:
        """Whether the kept point is better than controls ``u`` whose run is ``trajectory``."""
        return self.standing is not None and self.standing.beats(
            self._ranked(self.judge(u, trajectory)))

    def offer(self, u, where: str, *, trajectory=None, stage: int = 0, nit: int = 0) -> bool:
        """Keep controls ``u`` (``where`` says what they are: "its start", "stage 1's best";
        ``trajectory`` their run, simulated if not given) if they are at least as good as the
        kept point; a point whose simulation fails is no candidate (``stage``, ``nit``: for
        the checkpoint).  Whether it was kept."""
        try:
            if trajectory is None:
                trajectory = self.problem.simulate(u, records=False)
        except SimulationError:
            return False
        judged = self.judge(u, trajectory)
        if not self._ranked(judged).at_least(self.standing):
            return False
        self.u, self.trajectory, self.standing = u, trajectory, self._ranked(judged)
        self.where, self.objective = where, judged.objective
        if self.checkpoint is not None:
            self.checkpoint.write(u, judged, final=True, stage=stage, nit=nit,
                                  stage_dt=float(self.problem.dt))
        return True


def kept_outcome(kept, status: int, message: str) -> tuple[int, str]:
    """How a search ended that returns its ``kept`` point because what followed it ended
    worse (with ``status`` and ``message``): converged if the kept point meets the goal."""
    found = verdict(kept.goal, kept.trajectory)
    said = (f"{kept.where} (objective {kept.objective:.6g}) is kept: the search from it "
            f"ended worse ({message})")
    if found.met:
        return CONVERGED, f"converged: {said}; {found.describe()}"
    return (FAILED if status == CONVERGED else status), f"{said}; {found.describe()}"


def kept_stage(problem, stages: list, fun: float, status: int, message: str,
               seconds: float = 0.0) -> None:
    """Append to ``stages`` the record of returning the kept point (no iteration; its
    ``seconds``: work that ended without a record of its own, such as an interrupted
    finish's), so that the last stage's objective is the result's."""
    number = stages[-1]["stage"] + 1 if stages else 0
    stages.append(stage_record(problem, number, nit=0, nfev=0, njev=0, fun=fun,
                               status=status, message=message, seconds=seconds,
                               evaluation_seconds=0.0, failed_simulations=0))


def conclude(problem, kept, route, *, status: int, message: str, stages: list, history: list,
             method: str, started: float, known=None, gradient: bool = True,
             seconds: float = 0.0) -> Result:
    """The :class:`~.result.Result` at the point ``kept`` holds, ending with ``status`` and
    ``message`` and a stage that says so (``seconds``: see :func:`kept_stage`): its
    objective and gradient by ``route``, or ``known`` ``(controls, objective, gradient)``
    where the point is those controls, or (``gradient`` False, after a signal or the time
    limit: no more work) its objective alone, from its kept run."""
    u = kept.u
    if known is not None and (u is known[0] or np.array_equal(u, known[0])):
        fun, jac = known[1], known[2]
    elif gradient:
        fun, jac = evaluate_final(problem, route, u)
    else:
        fun = float(problem.state_cost(kept.trajectory, gradient=False)[0]
                    + problem.control_cost(u)[0])
        jac = np.full(u.size, np.nan)
    kept_stage(problem, stages, fun, status, message, seconds)
    return assemble(problem, u, fun=fun, jac=jac, status=status, message=message,
                    method=method, route=route, stages=stages, history=history,
                    started=started, trajectory=kept.trajectory)


def evaluate_final(problem, route, u):
    """Objective and gradient of ``problem`` at the controls ``u`` a search ends on (after a
    continuation stage stopped early, or the last round); if that is interrupted too, the
    objective alone (gradient NaN)."""
    try:
        f, g = route(problem, u)
        return float(f), g
    except KeyboardInterrupt:
        return float(problem.objective(u)), np.full(u.size, np.nan)
