"""The keyframes as a constraint on the controls of a window of late steps, and the control
cost's Hessian there.

:class:`KeyframeConstraint` is the keyframes' weighted residual ``r`` over their free
particles, linearized at a run as the residual family's one
:class:`~..residual.linearization.Linearization`: ``J du`` by one tangent pass from the
window's first frame (the integrator's exact ``step_jvp``), ``J^T w`` by one adjoint sweep
stopped there (``step_vjp``), both on the recorded run's factorisations.  The step that
holds them solves, at a run,

    minimise  0.5 (u + d)^T Q (u + d) + 0.5 damping d^T Q d   subject to   r + J d = 0

over the window's controls ``d`` (Q the control terms' Hessian, constant for quadratic
terms).  Its solution is ``d = projected / (1 + damping) + land``: ``land`` the least
change that puts the linearized keyframes on their targets (infinite damping; here in the
metric of Q's diagonal, :class:`~..residual.descents.Landing`), ``projected`` the control
cost's Newton step with the linearized keyframes left where they are
(:class:`~..residual.descents.Projected`), so every damping is tried without solving again.
:mod:`.searches` takes them apart: ``land`` to land, ``projected`` damped to lower the
effort.  The products are exact; a step solves its linear model to the solvers' tolerance.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ...objectives import StateKeyframe
from ...simulate import backward, tangent
from ..residual.linearization import Linearization

FALLBACK = (1e-3, 0.05)  # m, m/s: a row's tolerance if neither caller nor keyframe gives one
CG_RTOL = 1e-3  # the conjugate gradients' residual, relative to its right side or to the
# residual at the tolerances: far below what the linear model holds


class KeyframeConstraint:
    """The keyframes of ``problem`` at frames after ``first`` as a residual over their free
    particles, ``r = sqrt(weight) (state - target)`` stacked (its other goals refused; terms
    without a tolerance, such as a strain penalty, are not held), linearized at a run
    (:meth:`linearize`), and each row's tolerance: ``tolerances`` (position, velocity) where
    given, else its keyframe's own, else :data:`FALLBACK`."""

    def __init__(self, problem, first: int = 0, tolerances=(None, None)):
        self.problem, self.first = problem, int(first)
        others = [t.label for t in (problem.objective_terms.state_terms
                                    + problem.objective_terms.trajectory_terms)
                  if getattr(t, "has_tolerance", False) and not _held(t)]
        if others:
            raise ValueError(f"{problem.name}: holding keyframes as a constraint takes "
                             f"StateKeyframe goals only; the objective also has {others}: "
                             "remove them or solve the problem with solve()")
        model = problem.model
        free = model.free_mask().reshape(model.n, model.dim).all(axis=1)
        self.rows = []  # (frame, "x" or "v", particles, target, sqrt(weight), tolerance)
        for t in problem.objective_terms.state_terms:
            if not _held(t) or t.frame <= self.first:
                continue  # not a keyframe held here, or one the window's controls cannot move
            keep = free[t.particles] & getattr(t, "counted", True)
            declared = t.within or (None, None)
            for k, (kind, target, weight) in enumerate(
                    (("x", t.position_target, t.position_weight),
                     ("v", t.velocity_target, t.velocity_weight))):
                if target is not None and weight > 0 and keep.any():
                    tol = next(value for value in (tolerances[k], declared[k], FALLBACK[k])
                               if value is not None)
                    self.rows.append((t.frame, kind, t.particles[keep], target[keep],
                                      np.sqrt(weight), float(tol)))
        if not self.rows:
            raise ValueError(f"{problem.name}: no keyframe with free particles after frame "
                             f"{self.first}: nothing for the controls to hold")
        self.size = sum(row[2].size * model.dim for row in self.rows)
        self.tolerances = [row[5] for row in self.rows]
        # the residual's norm with every particle off by its row's tolerance
        self.scale = float(np.sqrt(sum(idx.size * (s * tol) ** 2
                                       for _, _, idx, _, s, tol in self.rows)))

    def residual(self, traj) -> np.ndarray:
        return np.concatenate([(s * (_frames(traj, kind)[frame][idx] - target)).ravel()
                               for frame, kind, idx, target, s, _ in self.rows])

    def linearize(self, traj) -> Linearization:
        """The residual at the recorded run ``traj`` with its products in the controls
        (``start``: the window's first frame, before which a change moves nothing): ``J du``
        by one tangent pass from there, ``J^T mu`` (the derivative of ``mu . r``) by one
        adjoint sweep stopped there."""
        p = self.problem

        def jvp(du):
            zero = np.zeros_like(p.x0)
            dx, dv = tangent(p.integrator, p.model, traj, zero, zero, p.controls.external(du),
                             start=self.first)
            return np.concatenate([(s * (dx if kind == "x" else dv)[frame][idx]).ravel()
                                   for frame, kind, idx, _, s, _ in self.rows])

        def vjp(mu):
            gx, gv = np.zeros_like(traj.x), np.zeros_like(traj.v)
            at = 0
            for frame, kind, idx, _, s, _ in self.rows:
                k = idx.size * p.model.dim
                (gx if kind == "x" else gv)[frame][idx] += (s * mu[at:at + k]
                                                            .reshape(idx.size, -1))
                at += k
            g_ext, g_start = backward(p.integrator, p.model, traj, gx, gv, stop=self.first)
            return p.controls.pullback(g_ext, g_start.v)

        return Linearization(self.residual(traj), jvp, vjp, size=p.size, trajectory=traj,
                             start=self.first)

    def misses(self, traj) -> list:
        """Per keyframe row: ``(kind, rms miss over its free particles)``."""
        return [(kind, float(np.sqrt(np.mean(np.sum((_frames(traj, kind)[frame][idx]
                                                      - target) ** 2, axis=1)))))
                for frame, kind, idx, target, _, _ in self.rows]

    def excess(self, traj) -> float:
        """The largest row's miss over its tolerance: at most 1 when every row holds."""
        return max(miss / tol for (_, miss), tol in zip(self.misses(traj), self.tolerances))


def _held(term) -> bool:
    """A goal held here: a StateKeyframe, its miss the rms distance over its (counted)
    particles; not a mesh keyframe that aligns its target (its miss is after a rigid
    motion)."""
    return isinstance(term, StateKeyframe) and not getattr(term, "align", False)


def _frames(traj, kind):
    return traj.x if kind == "x" else traj.v


def control_hessian(problem) -> sp.csc_matrix:
    """The control terms' Hessian Q (sparse; constant, for quadratic terms such as
    :class:`~casadi_keyframe.objectives.Smoothness`), from their CasADi expression."""
    U = ca.MX.sym("U", problem.size)
    H = ca.hessian(problem.control_expression(U), U)[0]
    fn = ca.Function("control_hessian", [U], [H])
    rows, cols = fn.sparsity_out(0).get_triplet()
    data = np.asarray(fn(np.zeros(problem.size)).nonzeros()).ravel()
    return sp.csc_matrix((data, (rows, cols)), shape=(problem.size,) * 2)


def factor_window(problem, Q, cols):
    """The LU factors of the control Hessian on the window's controls (ValueError if it is
    singular there: holding keyframes needs Smoothness with alpha > 0)."""
    try:
        Q_window = spla.splu(Q[cols][:, cols].tocsc())
        if not np.all(Q_window.U.diagonal() > 0):
            raise RuntimeError
    except RuntimeError:
        raise ValueError(f"{problem.name}: the control terms' Hessian is singular on the "
                         "window; holding keyframes needs Smoothness with alpha > 0") from None
    return Q_window
