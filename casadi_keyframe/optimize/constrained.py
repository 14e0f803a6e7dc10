"""Lower the control effort of controls that already hit their keyframes, keeping the hit.

A start that lands (a tracking guess, an earlier solve) sits where the keyframe penalty
curves so sharply, and the cloth's linearized steps jump so often (a spring's stiffness
changes as it crosses its rest length), that gradient methods on the penalty objective make
no progress.  :func:`lower_effort` treats the keyframes as a constraint instead: a
sequential quadratic step on the controls of the last ``window`` steps before the last
keyframe,

    minimise  0.5 (u + d)^T Q (u + d) + 0.5 damping d^T Q d   subject to   r + J d = 0,

with Q the control terms' Hessian (they are quadratic,
:class:`~casadi_keyframe.objectives.Smoothness`), r the keyframes' weighted residual
(positions and velocities of the free particles, the problem's own weights) and J its
Jacobian, built row by row from adjoint sweeps seeded at the keyframe frames
(:func:`~casadi_keyframe.simulate.backward` stopped at the window, reusing the forward
pass's factorisations).  A step is kept if the control cost falls and every keyframe's rms
position and velocity miss stays within the tolerances; otherwise the damping grows (the
step shrinks towards the pure re-landing) and the step is tried again.  The dynamics are
only piecewise smooth, so the landing is kept to those tolerances, not exactly.
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..adjoints import Adjoint
from ..controls import StepForces
from ..objectives import StateKeyframe
from ..simulate import backward
from ..state import SimulationError
from .outcome import CONVERGED, FAILED, LIMIT
from .result import Result, assemble, history_record, stage_record


class KeyframeConstraint:
    """The keyframes of ``problem`` at frames after ``first`` as a residual over their free
    particles, ``r = sqrt(weight) (state - target)`` stacked, with its Jacobian's transpose
    applied to a vector by one adjoint sweep (:meth:`vjp`)."""

    def __init__(self, problem, first: int = 0):
        self.problem, self.first = problem, int(first)
        others = [t.label for t in (problem.objective_terms.state_terms
                                    + problem.objective_terms.trajectory_terms)
                  if not isinstance(t, StateKeyframe)]
        if others:
            raise ValueError(f"{problem.name}: lower_effort holds StateKeyframe terms only; "
                             f"the objective also has {others}: remove them or solve the "
                             "problem with solve()")
        model = problem.model
        free = model.free_mask().reshape(model.n, model.dim).all(axis=1)
        self.rows = []  # (frame, "x" or "v", particles, target, sqrt(weight))
        for t in problem.objective_terms.state_terms:
            if t.frame <= self.first:
                continue  # the window's controls cannot move it
            keep = free[t.particles]
            for kind, target, weight in (("x", t.position_target, t.position_weight),
                                         ("v", t.velocity_target, t.velocity_weight)):
                if target is not None and weight > 0 and keep.any():
                    self.rows.append((t.frame, kind, t.particles[keep], target[keep],
                                      np.sqrt(weight)))
        if not self.rows:
            raise ValueError(f"{problem.name}: no keyframe with free particles after frame "
                             f"{self.first}: nothing for the controls to hold")
        self.size = sum(idx.size * model.dim for _, _, idx, _, _ in self.rows)

    def residual(self, traj) -> np.ndarray:
        return np.concatenate([(s * ((traj.x if kind == "x" else traj.v)[frame][idx]
                                     - target)).ravel()
                               for frame, kind, idx, target, s in self.rows])

    def vjp(self, traj, mu) -> np.ndarray:
        """``J^T mu``: the derivative of ``mu . r`` in the controls (zero before ``first``)."""
        p = self.problem
        gx, gv = np.zeros_like(traj.x), np.zeros_like(traj.v)
        at = 0
        for frame, kind, idx, _, s in self.rows:
            k = idx.size * p.model.dim
            (gx if kind == "x" else gv)[frame][idx] += s * mu[at:at + k].reshape(idx.size, -1)
            at += k
        g_ext, g_start = backward(p.integrator, p.model, traj, gx, gv, stop=self.first)
        return p.controls.pullback(g_ext, g_start.v)

    def misses(self, traj) -> list:
        """Per keyframe row: ``(kind, rms miss over its free particles)``."""
        return [(kind, float(np.sqrt(np.mean(np.sum(((traj.x if kind == "x" else traj.v)
                                                      [frame][idx] - target) ** 2, axis=1)))))
                for frame, kind, idx, target, _ in self.rows]


def control_hessian(problem) -> sp.csc_matrix:
    """The control terms' Hessian Q (sparse; constant, for quadratic terms such as
    :class:`~casadi_keyframe.objectives.Smoothness`), from their CasADi expression."""
    U = ca.MX.sym("U", problem.size)
    H = ca.hessian(problem.control_expression(U), U)[0]
    fn = ca.Function("control_hessian", [U], [H])
    rows, cols = fn.sparsity_out(0).get_triplet()
    data = np.asarray(fn(np.zeros(problem.size)).nonzeros()).ravel()
    return sp.csc_matrix((data, (rows, cols)), shape=(problem.size,) * 2)


def lower_effort(problem, *, window: int = 12, position_tolerance: float = 1e-3,
                 velocity_tolerance: float = 0.05, maxiter: int = 10, tries: int = 6,
                 damping: float = 0.0, u0=None, time_limit: float | None = None,
                 quiet: bool = True) -> Result:
    """Lower the control cost of ``u0`` (default: the problem's guess) while every
    StateKeyframe stays hit: rms miss over its free particles at most ``position_tolerance``
    (m) and ``velocity_tolerance`` (m/s), by the damped sequential quadratic steps of the
    module docstring on the controls of the last ``window`` steps before the last keyframe.

    Per iteration: one adjoint sweep over the window per residual row (6 per free particle
    of a full-state keyframe) and up to ``tries`` trial simulations; ``damping`` is the
    first trial's (it then grows 4x + 1 per rejected trial and shrinks 3x after a kept
    step).  Needs per-step forces (:class:`~casadi_keyframe.controls.StepForces`), a
    positive definite control Hessian on the window (Smoothness with ``alpha > 0``), an
    objective of StateKeyframe and control terms only, and a start within the tolerances.

    Returns a :class:`~.result.Result` (method "lower_effort"): status 0 when no trial
    step lowers the cost within the tolerances (or ``maxiter`` steps were kept), 1 at
    ``time_limit`` (seconds), 2 when the first iteration keeps no step; ``history`` has one
    record per kept step, ``stages`` one stage, ``njev`` counts the adjoint sweeps.
    """
    started = time.perf_counter()
    _check(problem, window=window, maxiter=maxiter, tries=tries,
           position_tolerance=position_tolerance, velocity_tolerance=velocity_tolerance,
           damping=damping)
    u = problem.initial_controls() if u0 is None else problem.controls.check(u0).copy()
    effort = _Effort(problem, window, {"x": position_tolerance, "v": velocity_tolerance},
                     damping, u, started)
    status, message = CONVERGED, f"{maxiter} steps kept (maxiter)"
    for _ in range(maxiter):
        if time_limit is not None and time.perf_counter() - started >= time_limit:
            status, message = LIMIT, f"time limit reached ({time_limit:g} s)"
            break
        if not effort.iterate(tries):
            status = CONVERGED if effort.history else FAILED
            message = (f"no step of {tries} tried lowers the control cost with the keyframes "
                       f"within {effort.tolerances} (damping up to {effort.damping:.3g})")
            break
    f, jac = Adjoint()(problem, effort.u)
    message = (f"{message}; {effort.sweeps} adjoint sweeps over "
               f"{effort.last - effort.first} steps")
    return assemble(problem, effort.u, fun=f, jac=jac, status=status, message=message,
                    method="lower_effort", gradient="adjoint",
                    stages=[effort.stage(f, status, message)], history=effort.history,
                    started=started, trajectory=effort.traj)


def _check(problem, **settings) -> None:
    """Refuse what lower_effort cannot hold or was given wrong, by name."""
    if not isinstance(problem.controls, StepForces):
        raise ValueError(f"{problem.name}: lower_effort needs per-step forces (StepForces), "
                         f"got {type(problem.controls).__name__}")
    for name in ("window", "maxiter", "tries"):
        value = settings[name]
        if not (isinstance(value, (int, np.integer)) and value >= 1):
            raise ValueError(f"lower_effort: {name} must be a whole number >= 1, got {value!r}")
    for name in ("position_tolerance", "velocity_tolerance", "damping"):
        value = settings[name]
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"lower_effort: {name} must be a number >= 0, got {value!r}")


class _Effort:
    """What :func:`lower_effort`'s iterations share: the window and its factorised control
    Hessian, the keyframe constraint and its tolerances, the point reached (``u``, its
    ``traj`` and control ``cost``), the damping, the history and the counts."""

    def __init__(self, problem, window, tolerances, damping, u, started):
        self.problem, self.tolerances, self.damping = problem, tolerances, damping
        self.started = started
        self.last = max(t.frame for t in problem.objective_terms.state_terms)
        self.first = max(self.last - window, 0)
        self.constraint = KeyframeConstraint(problem, self.first)
        block = problem.size // problem.steps
        self.cols = np.arange(self.first * block, self.last * block)  # the window's controls
        self.Q = control_hessian(problem)
        self.Q_window = _factor_window(problem, self.Q, self.cols)
        self.history, self.nfev, self.sweeps, self.failures = [], 1, 0, 0
        t = time.perf_counter()
        self.u, self.traj = u, problem.simulate(u)
        self.seconds = time.perf_counter() - t
        if not self.within(self.traj):
            raise ValueError(f"{problem.name}: the start misses its keyframes by "
                             f"{self.constraint.misses(self.traj)} (rms m, m/s), beyond the "
                             f"tolerances {tolerances}: lower_effort keeps a landing, it does "
                             "not find one; start from controls that land (a guess, a "
                             "solve's result)")
        self.cost = problem.control_cost(u)[0]
        state = problem.state_cost(self.traj, gradient=False)[0]
        self.start = (float(state + self.cost), float(state))  # objective, keyframe error

    def within(self, traj) -> bool:
        return all(miss <= self.tolerances[kind]
                   for kind, miss in self.constraint.misses(traj))

    def iterate(self, tries: int) -> bool:
        """One iteration: the step operator at the current point (one adjoint sweep per
        residual row), then up to ``tries`` damped trials; True if one was kept."""
        step = _step_operator(self.constraint, self.traj, self.Q_window, self.cols)
        self.sweeps += self.constraint.size
        r, g = self.constraint.residual(self.traj), (self.Q @ self.u)[self.cols]
        for _ in range(tries):
            trial_u = self.u.copy()
            trial_u[self.cols] += step(g, r, self.damping)
            trial_traj = self._simulate(trial_u)
            trial_cost = self.problem.control_cost(trial_u)[0]
            if trial_traj is not None and trial_cost < self.cost and self.within(trial_traj):
                self.u, self.traj, self.cost = trial_u, trial_traj, trial_cost
                self.damping /= 3.0
                self._record()
                return True
            self.damping = 4.0 * self.damping + 1.0
        return False

    def _simulate(self, u):
        """A trial's trajectory, or None if its simulation fails (counted and timed)."""
        t = time.perf_counter()
        self.nfev += 1
        try:
            return self.problem.simulate(u)
        except SimulationError:
            self.failures += 1
            return None
        finally:
            self.seconds += time.perf_counter() - t

    def _record(self) -> None:
        state = self.problem.state_cost(self.traj, gradient=False)[0]
        self.history.append(history_record(
            self.problem, self.u, objective=state + self.cost, keyframe_error=state,
            iteration=len(self.history) + 1, stage=0,
            seconds=time.perf_counter() - self.started, nfev=self.nfev,
            control_cost=self.cost, damping=self.damping,
            misses=self.constraint.misses(self.traj)))

    def stage(self, fun, status, message) -> dict:
        """The run's one :class:`~.result.Stage`."""
        return stage_record(self.problem, 0, nit=len(self.history), nfev=self.nfev,
                            njev=self.sweeps, fun=fun, status=status, message=message,
                            seconds=time.perf_counter() - self.started,
                            evaluation_seconds=self.seconds,
                            failed_simulations=self.failures, start=self.start)


def _factor_window(problem, Q, cols):
    """The LU factors of the control Hessian on the window's controls (ValueError if it is
    singular there: lower_effort needs Smoothness with alpha > 0)."""
    try:
        Q_window = spla.splu(Q[cols][:, cols].tocsc())
        if not np.all(Q_window.U.diagonal() > 0):
            raise RuntimeError
    except RuntimeError:
        raise ValueError(f"{problem.name}: the control terms' Hessian is singular on the "
                         "window; lower_effort needs Smoothness with alpha > 0") from None
    return Q_window


def _step_operator(constraint, traj, Q_window, cols):
    """The damped step ``d(g, r, damping)`` at ``traj``: J from one adjoint sweep per
    residual row, the constraint block ``J Q^-1 J^T`` inverted on its well-conditioned part
    (eigenvalues below 1e-12 of the largest dropped: directions the window cannot steer)."""
    identity = np.eye(constraint.size)
    JT = np.stack([constraint.vjp(traj, e)[cols] for e in identity], axis=1)
    QiJT = Q_window.solve(JT)
    vals, vecs = np.linalg.eigh(JT.T @ QiJT)
    keep = vals > 1e-12 * vals.max()
    pinv = (vecs[:, keep] / vals[keep]) @ vecs[:, keep].T

    def step(g, r, damping):
        gi = Q_window.solve(g) / (1.0 + damping)
        return -gi + QiJT @ (pinv @ (JT.T @ gi - r))
    return step
