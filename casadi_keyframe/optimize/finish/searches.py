"""Keyframes held as a constraint while the controls of the last steps before them change:
:func:`land` puts missed keyframes within their tolerances with the least change of the
controls, :func:`lower_effort` lowers the control cost of controls that land and keeps them
landed.

A start that lands (a tracking guess, an earlier solve) sits where the keyframe penalty
curves so sharply, and the cloth's linearized steps switch so often (a spring crossing its
rest length, a contact held or let go), that gradient methods on the penalty objective make
no progress there; a search that stops a little off its keyframes stalls at the same kinks.
Both functions work on the controls of the last ``window`` steps before the last keyframe,
whose effect on the keyframes is short and nearly linear, with the matrix-free steps of
:mod:`.window_step`.  A landing step is halved until the largest miss (over its tolerance)
falls.  An effort step (the control cost's Newton step that leaves the linearized misses
as they are) is damped until its trial, after at most ``restore`` landing steps from it, is
within the tolerances at a lower control cost: a step that leaves the keyframes by a jump
of the piecewise smooth dynamics is put back, not thrown away.
"""
from __future__ import annotations

import numpy as np

from ...adjoints import get_gradient
from ...controls import StepForces
from ...state import SimulationError
from ..deadline import Deadline, now
from ..kept import Standing
from ..outcome import CONVERGED, FAILED, LIMIT
from ..result import Result, assemble, history_record, stage_record
from .constraint import KeyframeConstraint, WindowStep, control_hessian, factor_window

__all__ = ["KeyframeConstraint", "control_hessian", "land", "lower_effort"]

LANDED = 0.8  # land() goes on until every miss is within this share of its tolerance


def land(problem, *, u0=None, window: int = 12, position_tolerance: float | None = None,
         velocity_tolerance: float | None = None, maxiter: int = 10, tries: int = 4,
         iterations: int = 60, time_limit: float | None = None, on_keep=None,
         deadline: Deadline | None = None, gradient=None) -> Result:
    """Put the StateKeyframes of controls ``u0`` (default: the problem's start) within their
    tolerances (``position_tolerance`` m and ``velocity_tolerance`` m/s where given, else
    each keyframe's own) by landing steps on the controls of the last ``window``
    steps before the last keyframe: each the least squares landing of the linearized
    keyframes with the least change (LSMR, in the metric of the control cost's Hessian's
    diagonal; a miss the window cannot steer is left), tried at most ``tries`` times, halved
    each time,
    until the largest miss over its tolerance falls (a motion within the physical limits
    staying so), until every miss is within :data:`LANDED` of its tolerance (a margin for
    what follows).  ``iterations``: LSMR iterations per step; ``on_keep(u, trajectory)`` is
    called with each kept step (a checkpoint); ``deadline``: a solve's
    :class:`~.deadline.Deadline`, in place of ``time_limit``; ``gradient``: the route (name
    or object, default the registry's) of the result's gradient.

    Returns a :class:`~.result.Result` (method "land"): status 0 if it ends within the
    tolerances, else 2 when no step brings the keyframes closer, 1 at ``maxiter`` or
    ``time_limit`` (s).
    """
    started, deadline = now(), deadline or Deadline.start(time_limit)
    _check(problem, window=window, maxiter=maxiter, tries=tries, iterations=iterations,
           position_tolerance=position_tolerance, velocity_tolerance=velocity_tolerance)
    held = _Held(problem, window, (position_tolerance, velocity_tolerance), u0, started,
                 iterations, on_keep=on_keep, route=get_gradient(gradient))
    status, message = None, ""
    for _ in range(maxiter):
        if held.within(held.traj, LANDED):
            break
        if deadline.passed():
            status, message = LIMIT, f"time limit reached ({deadline.limit:g} s)"
            break
        if not held.land(tries):
            status, message = FAILED, (f"no landing step of {tries} tried brings the keyframes "
                                       "closer")
            break
    if held.within(held.traj):
        status, message = CONVERGED, "every keyframe within its tolerances"
    elif status is None:
        status, message = LIMIT, f"{maxiter} landing steps taken (maxiter), still off"
    message = f"{message}: misses {_said(held.constraint.misses(held.traj))}"
    return held.result("land", status, message)


def lower_effort(problem, *, window: int = 12, position_tolerance: float | None = None,
                 velocity_tolerance: float | None = None, maxiter: int = 10, tries: int = 6,
                 damping: float = 0.0, restore: int = 2, iterations: int = 60, u0=None,
                 time_limit: float | None = None, keep_objective: bool = False,
                 on_keep=None, quiet: bool = True, deadline: Deadline | None = None,
                 gradient=None) -> Result:
    """Lower the control cost of ``u0`` (default: the problem's start) while every
    StateKeyframe stays within its tolerance (as for :func:`land`), by damped steps on the
    controls of the last ``window`` steps before the last keyframe (module docstring):
    ``damping`` is the first trial's (it grows 4x + 1 per rejected trial, at most ``tries``
    per iteration, and shrinks 3x after a kept step); a trial off the keyframes gets up to
    ``restore`` landing steps; ``keep_objective``: a step must not raise the objective
    either (keyframe misses traded for effort only where the objective gains).  Needs
    per-step forces (:class:`~casadi_keyframe.controls.StepForces`), a positive definite
    control Hessian on the window (Smoothness with ``alpha > 0``), goals that are
    StateKeyframes only (a penalty without a tolerance, such as StrainLimit, is not held:
    ``keep_objective`` weighs it), and a start within the tolerances (:func:`land` finds
    one); ``on_keep``, ``deadline`` and ``gradient`` as for :func:`land`.

    Returns a :class:`~.result.Result` (method "lower_effort"): status 0 when no trial
    step lowers the cost within the tolerances (or ``maxiter`` steps were kept), 1 at
    ``time_limit`` (seconds), 2 when the first iteration keeps no step; ``history`` has one
    record per kept step, ``stages`` one stage, ``njev`` counts the sweeps over the window.
    """
    started, deadline = now(), deadline or Deadline.start(time_limit)
    _check(problem, window=window, maxiter=maxiter, tries=tries, iterations=iterations,
           position_tolerance=position_tolerance, velocity_tolerance=velocity_tolerance,
           damping=damping, restore=restore)
    held = _Held(problem, window, (position_tolerance, velocity_tolerance), u0, started,
                 iterations, damping=damping, keep_objective=keep_objective,
                 on_keep=on_keep, route=get_gradient(gradient))
    if not held.within(held.traj):
        raise ValueError(f"{problem.name}: the start misses its keyframes by "
                         f"{held.constraint.misses(held.traj)} (rms m, m/s), beyond the "
                         f"tolerances {held.constraint.tolerances}: lower_effort keeps a "
                         "landing, it does not find one; start from controls that land (a "
                         "guess, a solve's result, land())")
    status, message = CONVERGED, f"{maxiter} steps kept (maxiter)"
    for _ in range(maxiter):
        if deadline.passed():
            status, message = LIMIT, f"time limit reached ({deadline.limit:g} s)"
            break
        if not held.lower(tries, restore):
            status = CONVERGED if held.history else FAILED
            kept = f"{len(held.history)} steps kept, then " if held.history else ""
            message = (f"{kept}no step of {tries} tried lowers the control cost with the "
                       f"keyframes within their tolerances (damping up to {held.damping:.3g})")
            break
    return held.result("lower_effort", status, message)


def _said(misses) -> str:
    units = {"x": "m", "v": "m/s"}
    return ", ".join(f"{miss:.3g} {units[kind]}" for kind, miss in misses)



def _check(problem, **settings) -> None:
    """Refuse what the held keyframes cannot do or were given wrong, by name."""
    if not isinstance(problem.controls, StepForces):
        raise ValueError(f"{problem.name}: holding keyframes needs per-step forces "
                         f"(StepForces), got {type(problem.controls).__name__}")
    for name in ("window", "maxiter", "tries", "iterations", "restore"):
        value = settings.get(name, 1)
        least = 0 if name == "restore" else 1
        if not (isinstance(value, (int, np.integer)) and value >= least):
            raise ValueError(f"{name} must be a whole number >= {least}, got {value!r}")
    for name in ("position_tolerance", "velocity_tolerance", "damping"):
        value = settings.get(name)
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a number >= 0, got {value!r}")


class _Held:
    """What the iterations of :func:`land` and :func:`lower_effort` share: the window and
    its factorised control Hessian, the keyframe constraint with its tolerances, the point
    reached (``u``, its ``traj`` and control ``cost``), the damping, the history and the
    counts (simulations, sweeps, failed simulations, seconds simulating)."""

    def __init__(self, problem, window, tolerances, u, started, iterations, damping=0.0,
                 keep_objective=False, on_keep=None, route=None):
        self.problem, self.started, self.iterations = problem, started, iterations
        self.route = route
        self.damping, self.keep_objective, self.on_keep = damping, keep_objective, on_keep
        self.last = max((t.frame for t in problem.objective_terms.state_terms), default=0)
        self.first = max(self.last - window, 0)
        self.constraint = KeyframeConstraint(problem, self.first, tolerances)
        block = problem.size // problem.steps
        self.cols = np.arange(self.first * block, self.last * block)  # the window's controls
        self.Q = control_hessian(problem)
        self.Q_window = factor_window(problem, self.Q, self.cols)
        self.Q_diagonal = self.Q.diagonal()[self.cols]
        self.history, self.nfev, self.sweeps, self.failures, self.seconds = [], 0, 0, 0, 0.0
        u = problem.initial_controls() if u is None else problem.controls.check(u).copy()
        self.u, self.traj = u, self._simulate(u)
        if self.traj is None:
            raise SimulationError(f"{problem.name}: the simulation fails at the starting "
                                  "controls", None)
        self.cost = problem.control_cost(u)[0]
        objective = self.objective(u, self.traj)
        self.start = (objective, objective - float(self.cost))  # objective, keyframe error

    def within(self, traj, share: float = 1.0) -> bool:
        """Every row within ``share`` of its tolerance, the motion within the physical
        limits."""
        return self.constraint.excess(traj) <= share and self.physical(traj)

    def physical(self, traj) -> bool:
        return not list(self.problem.physical_shortfall(traj))

    def objective(self, u, traj) -> float:
        return float(self.problem.state_cost(traj, gradient=False)[0]
                     + self.problem.control_cost(u)[0])

    def _step(self, traj) -> WindowStep:
        return WindowStep(self.constraint, traj, self.Q_window, self.cols, self.Q_diagonal,
                          self.iterations)

    def land(self, tries: int) -> bool:
        """One landing step at the current point, halved until the largest miss over its
        tolerance falls, a whole motion staying whole (at most ``tries`` trials); True if
        one was kept."""
        step = self._step(self.traj)
        d = step.land()
        self.sweeps += step.products
        excess, whole = self.constraint.excess(self.traj), self.physical(self.traj)
        for k in range(tries):
            trial_u = self.u.copy()
            trial_u[self.cols] += 0.5 ** k * d
            traj = self._simulate(trial_u)
            if (traj is not None and self.constraint.excess(traj) < excess
                    and (self.physical(traj) or not whole)):
                self._keep(trial_u, traj)
                return True
        return False

    def lower(self, tries: int, restore: int) -> bool:
        """One effort iteration: the projected step at the current point (the keyframes'
        misses left as they are, to first order), then up to ``tries`` damped trials, each
        landed again by up to ``restore`` landing steps if it leaves the tolerances; True
        if one was kept (within the tolerances, at a lower control cost)."""
        step = self._step(self.traj)
        projected = step.projected((self.Q @ self.u)[self.cols])
        self.sweeps += step.products
        for _ in range(tries):
            trial_u = self.u.copy()
            trial_u[self.cols] += projected / (1.0 + self.damping)
            found = self._restored(trial_u, restore)
            if found is not None and self._better(*found):
                self._keep(*found)
                self.damping /= 3.0
                return True
            self.damping = 4.0 * self.damping + 1.0
        return False

    def _better(self, u, traj) -> bool:
        """A lower control cost (and, with ``keep_objective``, no higher objective), ranked
        as every point is (:class:`~.kept.Standing`; a trial here is within the tolerances)."""
        if not Standing(True, self.problem.control_cost(u)[0]).beats(Standing(True, self.cost)):
            return False
        return not self.keep_objective or Standing(True, self.objective(u, traj)).at_least(
            Standing(True, self.objective(self.u, self.traj)))

    def _restored(self, u, restore: int):
        """``(u, traj)`` within the tolerances after at most ``restore`` landing steps from
        the controls ``u``, or None."""
        traj = self._simulate(u)
        for _ in range(restore):
            if traj is None or self.within(traj):
                break
            step = self._step(traj)
            u = u.copy()
            u[self.cols] += step.land()
            self.sweeps += step.products
            traj = self._simulate(u)
        return (u, traj) if traj is not None and self.within(traj) else None

    def _simulate(self, u):
        """A trial's trajectory, or None if its simulation fails (counted and timed)."""
        t = now()
        self.nfev += 1
        try:
            return self.problem.simulate(u)
        except SimulationError:
            self.failures += 1
            return None
        finally:
            self.seconds += now() - t

    def _keep(self, u, traj) -> None:
        self.u, self.traj, self.cost = u, traj, self.problem.control_cost(u)[0]
        if self.on_keep is not None:
            self.on_keep(u, traj)
        state = self.problem.state_cost(traj, gradient=False)[0]
        self.history.append(history_record(
            self.problem, u, objective=state + self.cost, keyframe_error=state,
            iteration=len(self.history) + 1, stage=0,
            seconds=now() - self.started, nfev=self.nfev,
            control_cost=self.cost, damping=self.damping,
            misses=self.constraint.misses(traj)))

    def result(self, method: str, status: int, message: str) -> Result:
        """The :class:`~.result.Result` at the point reached, with its one stage."""
        f, jac = self.route(self.problem, self.u)
        message = (f"{message}; {self.sweeps} sweeps over the {self.last - self.first} steps "
                   f"before frame {self.last}")
        stage = stage_record(self.problem, 0, nit=len(self.history), nfev=self.nfev,
                             njev=self.sweeps, fun=f, status=status, message=message,
                             seconds=now() - self.started,
                             evaluation_seconds=self.seconds,
                             failed_simulations=self.failures, start=self.start)
        return assemble(self.problem, self.u, fun=f, jac=jac, status=status, message=message,
                        method=method, route=self.route, stages=[stage],
                        history=self.history, started=self.started, trajectory=self.traj)
