"""The best point a solve has seen on its final problem, judged by the goal first and then by
the objective (:class:`Kept`): what it returns when its stages (coarser meshes, a homotopy,
multiple shooting, a resumed run's start) end worse than an earlier point, so that no solve
returns a point worse than its start."""
from __future__ import annotations

from ..state import SimulationError
from .goal import verdict
from .outcome import CONVERGED, FAILED
from .result import stage_record


class Kept:
    """The best point offered so far on ``problem``, judged by ``goal`` (its terms and
    limits: met first, then, ``by_objective``, the lower objective on its targets; a later
    point wins a tie); each better point is also offered to the ``checkpoint`` (or None).
    Rounds of hard keyframes rank by the goal alone: each round trades objective for a
    smaller miss on purpose."""

    def __init__(self, problem, goal, checkpoint, *, by_objective: bool = True):
        self.problem, self.goal, self.checkpoint = problem, goal, checkpoint
        self.by_objective = by_objective
        self.u = self.trajectory = self.key = self.objective = None
        self.where = ""

    def judge(self, u, trajectory) -> tuple[bool, float]:
        """``(met, objective)`` of controls ``u`` whose run is ``trajectory``."""
        fun = (self.goal.state_cost(trajectory, gradient=False)[0]
               + self.goal.control_cost(u)[0])
        return verdict(self.goal, trajectory).met, float(fun)

    def rank(self, met: bool, fun: float) -> tuple:
        return (met, -fun) if self.by_objective else (met,)

    def beats(self, u, trajectory) -> bool:
        """Whether the kept point is better than controls ``u`` whose run is ``trajectory``."""
        return self.key is not None and self.key > self.rank(*self.judge(u, trajectory))

    def offer(self, u, where: str, *, trajectory=None, stage: int = 0, nit: int = 0) -> bool:
        """Keep controls ``u`` (``where`` says what they are: "its start", "stage 1's best";
        ``trajectory`` their run, simulated if not given) if they are better than the kept
        point; a point whose simulation fails is no candidate (``stage``, ``nit``: for the
        checkpoint).  Whether it was kept."""
        try:
            if trajectory is None:
                trajectory = self.problem.simulate(u, records=False)
        except SimulationError:
            return False
        met, fun = self.judge(u, trajectory)
        if self.key is not None and self.rank(met, fun) < self.key:
            return False
        self.u, self.trajectory, self.key, self.where = u, trajectory, self.rank(met, fun), where
        self.objective = fun
        if self.checkpoint is not None:
            self.checkpoint.write(u, fun=fun, met=met, final=True, stage=stage, nit=nit,
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


def kept_stage(problem, stages: list, fun: float, status: int, message: str) -> None:
    """Append to ``stages`` the record of returning the kept point (no iteration), so that
    the last stage's objective is the result's."""
    number = stages[-1]["stage"] + 1 if stages else 0
    stages.append(stage_record(problem, number, nit=0, nfev=0, njev=0, fun=fun,
                               status=status, message=message, seconds=0.0,
                               evaluation_seconds=0.0, failed_simulations=0))
