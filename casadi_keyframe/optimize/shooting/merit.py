"""Multiple shooting's merit as the optimizer's :class:`~.evaluator.Evaluator` evaluates
it: :class:`ShootingMerit`, a function of the stacked variables z (controls and node
states) returning a :class:`ShootingEvaluation`, and what an iteration's record and the goal
check read from it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...adjoints import Evaluation
from ..goal import verdict
from .residuals import linearize_shooting


@dataclass(frozen=True)
class ShootingEvaluation(Evaluation):
    """The merit at a point (``value``, ``gradient`` in z, ``trajectory`` the stitched
    segments) and what it is made of: the problem's ``objective`` on the stitched run, its
    ``keyframe_error`` part and the scaled ``defects`` (``(c_x, c_v)`` per node)."""

    objective: float = np.nan
    keyframe_error: float = np.nan
    defects: tuple = ()


class ShootingMerit:
    """The merit of ``shooting`` (:meth:`~.form.Shooting.evaluate`) with its segments swept by
    ``runner`` and its defects held by ``mult`` (None: the objective alone, the defects
    held as constraints elsewhere).  ``problem`` is the stage's own: its true keyframe
    targets describe a point and its controls' run judges the goal (the rounds' aim lives
    in ``shooting.problem``)."""

    route = None  # its sweeps run no gradient route: nothing for the health log to read

    def __init__(self, problem, shooting, runner, mult):
        self.problem, self.shooting, self.runner, self.mult = problem, shooting, runner, mult

    def __call__(self, z) -> ShootingEvaluation:
        """The merit's evaluation at ``z`` (see :meth:`~.form.Shooting.evaluate`)."""
        merit, gradient, info = self.shooting.evaluate(z, self.runner, self.mult)
        return ShootingEvaluation(merit, gradient, info["trajectory"],
                                  objective=info["objective"],
                                  keyframe_error=info["keyframe_error"],
                                  defects=tuple(info["defects"]))

    def linearize(self, z):
        """Its residual form at z (:func:`~.residuals.linearize_shooting`), for a residual
        search."""
        return linearize_shooting(self, z)

    def describe(self, z, f, info):
        """``(controls, objective, keyframe error, {"defect": ...})`` of an evaluated point:
        the problem's objective on its stitched trajectory, its largest scaled defect."""
        u = self.shooting.unpack(z)[0]
        keyframe, objective = true_objective(self.problem, u, info)
        return u, objective, keyframe, {"defect": self.shooting.defect_size(info.defects)}

    def meets(self, goal, info) -> bool:
        """Never judged met on its own: a stitched run is not the controls' run (the rounds
        rank points by the merit alone; the stage's result is judged as a run)."""
        return False

    def may_meet(self, goal, info) -> bool:
        """Whether the point may meet ``goal``: its defects within their tolerance and its
        stitched trajectory meeting it (then its controls' own run is judged)."""
        return (self.shooting.defect_size(info.defects) <= 1.0
                and verdict(goal, info.trajectory).met)

    def run(self, z, info):
        """The run of z's controls from the start, one trajectory (no records)."""
        return self.problem.simulate(self.shooting.unpack(z)[0], records=False)


def true_objective(problem, u, info) -> tuple[float, float]:
    """``(keyframe error, objective)`` of ``problem`` (its true targets, not a round's aim)
    on the stitched trajectory of an evaluation (``info``), at controls ``u``."""
    keyframe = problem.state_cost(info.trajectory, gradient=False)[0]
    return keyframe, keyframe + problem.control_cost(u)[0]
