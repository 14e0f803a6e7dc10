"""What the finish's searches share (:class:`WindowSearch`): the window of late steps they
move, the keyframes they hold there, the point they have reached, and the one
:class:`~..evaluator.Evaluator` that judges every trial.

A trial is judged by its value and run alone (no gradient: the steps come from the held
keyframes' linearization, :meth:`~.constraint.KeyframeConstraint.linearize`), counted,
timed and checked for a signal by the evaluator; a kept step is the evaluator's last point,
so its record is the evaluator's too.
"""
from __future__ import annotations

import numpy as np

from ...state import SimulationError
from ..deadline import Deadline
from ..evaluator import Evaluator
from ..kept import Standing
from ..result import Result, assemble, stage_record
from ..residual.descents import Landing, Projected
from .constraint import CG_RTOL, KeyframeConstraint, control_hessian, factor_window


class WindowSearch:
    """The controls of the last ``window`` steps before the last keyframe of ``problem``
    (``cols``, the control Hessian ``Q`` factored there), the keyframes held there
    (:class:`~.constraint.KeyframeConstraint`, with ``tolerances``), the point reached from
    ``u`` (``u``, its run ``traj``, its objective ``value`` and control ``cost``), the
    evaluator judging the trials (``ev``) and the history of kept steps.  ``iterations``:
    LSMR's and conjugate gradients' per step; ``route``: the result's gradient route;
    ``keep_objective``: an effort step must not raise the objective; ``on_keep(u,
    trajectory)`` is called with each kept step."""

    def __init__(self, problem, window, tolerances, u, iterations, route, *,
                 keep_objective=False, on_keep=None):
        self.problem, self.iterations, self.route = problem, iterations, route
        self.keep_objective, self.on_keep = keep_objective, on_keep
        self.last = max((t.frame for t in problem.objective_terms.state_terms), default=0)
        self.first = max(self.last - window, 0)
        self.constraint = KeyframeConstraint(problem, self.first, tolerances)
        block = problem.size // problem.steps
        self.cols = np.arange(self.first * block, self.last * block)  # the window's controls
        self.Q = control_hessian(problem)
        self.Q_window = factor_window(problem, self.Q, self.cols)
        self.Q_diagonal = self.Q.diagonal()[self.cols]
        self.ev = Evaluator(problem, route, None, report="last")
        self.history, self.sweeps, self.clock = [], 0, Deadline.start()
        u = problem.initial_controls() if u is None else problem.controls.check(u).copy()
        found = self.ev.judge(u, records=True)
        if found is None:
            raise SimulationError(f"{problem.name}: the simulation fails at the starting "
                                  "controls", None)
        self.u, self.traj, self.value = u, found.trajectory, found.value
        self.cost = problem.control_cost(u)[0]
        self.ev.start = (self.value, self.value - float(self.cost))  # objective, keyframe error

    def within(self, traj, share: float = 1.0) -> bool:
        """Every row within ``share`` of its tolerance, the motion within the physical
        limits."""
        return self.constraint.excess(traj) <= share and self.physical(traj)

    def physical(self, traj) -> bool:
        return not list(self.problem.physical_shortfall(traj))

    def _landing(self, traj) -> Landing:
        lin = self.constraint.linearize(traj)
        step = Landing(lin, self.cols, self.Q_diagonal, self.iterations, CG_RTOL)
        self.sweeps += lin.products
        return step

    def land(self, rule) -> bool:
        """One landing step at the current point, sized by ``rule`` (a
        :class:`~..residual.steps.Halving`) until the largest miss over its tolerance falls,
        a whole motion staying whole; True if one was kept."""
        step = self._landing(self.traj)
        excess, whole = self.constraint.excess(self.traj), self.physical(self.traj)
        for size in rule.sizes():
            trial = self.u.copy()
            trial[self.cols] += step.step(size)
            found = self.ev.judge(trial, records=True)
            if (found is not None and self.constraint.excess(found.trajectory) < excess
                    and (self.physical(found.trajectory) or not whole)):
                self._keep(trial, found)
                return True
        return False

    def lower(self, rule, restore: int) -> bool:
        """One effort iteration: the projected step at the current point (the keyframes'
        misses left as they are, to first order), damped by ``rule`` (a
        :class:`~..residual.steps.Damping`), each trial landed again by up to ``restore``
        landing steps if it leaves the tolerances; True if one was kept (within the
        tolerances, at a lower control cost)."""
        lin = self.constraint.linearize(self.traj)
        step = Projected(lin, self.cols, self.Q_window, (self.Q @ self.u)[self.cols],
                         self.iterations, CG_RTOL, CG_RTOL * self.constraint.scale)
        self.sweeps += lin.products
        for damping in rule.sizes():
            trial = self.u.copy()
            trial[self.cols] += step.step(damping)
            found = self._restored(trial, restore)
            if found is not None and self._better(*found):
                self._keep(*found, damping=damping)
                rule.taken()
                return True
            rule.refused()
        return False

    def _better(self, u, found) -> bool:
        """A lower control cost (and, with ``keep_objective``, no higher objective), ranked
        as every point is (:class:`~..kept.Standing`; a trial here is within the
        tolerances)."""
        if not Standing(True, self.problem.control_cost(u)[0]).beats(Standing(True, self.cost)):
            return False
        return not self.keep_objective or Standing(True, found.value).at_least(
            Standing(True, self.value))

    def _restored(self, u, restore: int):
        """``(u, evaluation)`` within the tolerances after at most ``restore`` landing steps
        from the controls ``u``, or None."""
        found = self.ev.judge(u, records=True)
        for _ in range(restore):
            if found is None or self.within(found.trajectory):
                break
            step = self._landing(found.trajectory)
            u = u.copy()
            u[self.cols] += step.step(1.0)
            found = self.ev.judge(u, records=True)
        return (u, found) if found is not None and self.within(found.trajectory) else None

    def _keep(self, u, found, damping: float = 0.0) -> None:
        """Step to ``u`` (the evaluator's last point, ``found``) and record it."""
        self.u, self.traj, self.value = u, found.trajectory, found.value
        self.cost = self.problem.control_cost(u)[0]
        if self.on_keep is not None:
            self.on_keep(u, found.trajectory)
        self.ev.record(self.history, self.clock, control_cost=self.cost, damping=damping,
                       misses=self.constraint.misses(found.trajectory))

    def result(self, method: str, status: int, message: str) -> Result:
        """The :class:`~..result.Result` at the point reached, with its one stage (``njev``:
        the sweeps over the window)."""
        f, jac = self.route(self.problem, self.u)
        message = (f"{message}; {self.sweeps} sweeps over the {self.last - self.first} steps "
                   f"before frame {self.last}")
        stage = stage_record(self.problem, 0, nit=len(self.history), fun=f, status=status,
                             message=message, seconds=self.clock.elapsed(),
                             start=self.ev.start, **{**self.ev.counts(), "njev": self.sweeps})
        return assemble(self.problem, self.u, fun=f, jac=jac, status=status, message=message,
                        method=method, route=self.route, stages=[stage],
                        history=self.history, started=self.clock.started, trajectory=self.traj)
