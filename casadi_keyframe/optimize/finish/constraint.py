"""The keyframes as a constraint on the controls of a window of late steps, and the
quadratic step that holds them, matrix-free.

:class:`KeyframeConstraint` is the keyframes' weighted residual ``r`` over their free
particles with its Jacobian ``J`` applied both ways: ``J du`` by one tangent pass from the
window's first frame (the integrator's exact ``step_jvp``), ``J^T w`` by one adjoint sweep
stopped there (``step_vjp``), both on the recorded run's factorisations.
:class:`WindowStep` solves, at a run,

    minimise  0.5 (u + d)^T Q (u + d) + 0.5 damping d^T Q d   subject to   r + J d = 0

over the window's controls ``d`` (Q the control terms' Hessian, constant for quadratic
terms).  Its solution is ``d = projected / (1 + damping) + land``: ``land`` the least
change that puts the linearized keyframes on their targets (infinite damping; here in the
metric of Q's diagonal),
``projected`` the control cost's Newton step with the linearized keyframes left where they
are (conjugate gradients on ``(J Q^-1 J^T) y = J Q^-1 g``, an iteration one sweep each
way over the window), so every damping is tried without solving again.  :mod:`.constrained`
takes them apart: ``land`` (by LSMR, the least squares solution where the window cannot
land the keyframes exactly) to land, ``projected`` scaled to lower the effort.  The
products are exact; a step solves its linear model to the solvers' tolerance.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ...objectives import StateKeyframe
from ...simulate import backward, tangent

FALLBACK = (1e-3, 0.05)  # m, m/s: a row's tolerance if neither caller nor keyframe gives one
CG_RTOL = 1e-3  # the conjugate gradients' residual, relative to its right side or to the
# residual at the tolerances: far below what the linear model holds


class KeyframeConstraint:
    """The keyframes of ``problem`` at frames after ``first`` as a residual over their free
    particles, ``r = sqrt(weight) (state - target)`` stacked (its other goals refused; terms
    without a tolerance, such as a strain penalty, are not held), with its Jacobian applied
    to a change of the controls (:meth:`jvp`) and its transpose to a cotangent
    (:meth:`vjp`), and each row's tolerance: ``tolerances`` (position, velocity) where
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

    def jvp(self, traj, du) -> np.ndarray:
        """``J du``: the residual's change along the controls' change ``du`` (zero before
        ``first``), by one tangent pass from frame ``first``."""
        p = self.problem
        zero = np.zeros_like(p.x0)
        dx, dv = tangent(p.integrator, p.model, traj, zero, zero, p.controls.external(du),
                         start=self.first)
        return np.concatenate([(s * (dx if kind == "x" else dv)[frame][idx]).ravel()
                               for frame, kind, idx, _, s, _ in self.rows])

    def vjp(self, traj, mu) -> np.ndarray:
        """``J^T mu``: the derivative of ``mu . r`` in the controls (zero before ``first``)."""
        p = self.problem
        gx, gv = np.zeros_like(traj.x), np.zeros_like(traj.v)
        at = 0
        for frame, kind, idx, _, s, _ in self.rows:
            k = idx.size * p.model.dim
            (gx if kind == "x" else gv)[frame][idx] += s * mu[at:at + k].reshape(idx.size, -1)
            at += k
        g_ext, g_start = backward(p.integrator, p.model, traj, gx, gv, stop=self.first)
        return p.controls.pullback(g_ext, g_start.v)

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


class WindowStep:
    """The module docstring's step at the recorded run ``traj``: :meth:`land` and
    :meth:`projected`, the two parts of the window's change ``d``; ``products`` counts the
    sweeps (one tangent or adjoint pass over the window each), at most ``iterations``
    iterations per solve (LSMR's or the conjugate gradients')."""

    def __init__(self, constraint, traj, Q_window, cols, Q_diagonal, iterations: int = 60):
        self.constraint, self.traj, self.Q_window, self.cols = constraint, traj, Q_window, cols
        self.Q_diagonal = Q_diagonal
        self.iterations, self.products = iterations, 0
        self.r = constraint.residual(traj)
        self.size = constraint.problem.size

    def _J(self, d_window) -> np.ndarray:
        du = np.zeros(self.size)
        du[self.cols] = d_window
        self.products += 1
        return self.constraint.jvp(self.traj, du)

    def _JT(self, y) -> np.ndarray:
        self.products += 1
        return self.constraint.vjp(self.traj, y)[self.cols]

    def _QiJT(self, y) -> np.ndarray:
        return self.Q_window.solve(self._JT(y))

    def _solve(self, b) -> np.ndarray:
        """``y`` with ``(J Q^-1 J^T) y = b`` by conjugate gradients from zero."""
        m = self.r.size
        A = spla.LinearOperator((m, m), matvec=lambda y: self._J(self._QiJT(y)), dtype=float)
        y, _ = spla.cg(A, b, rtol=CG_RTOL, atol=CG_RTOL * self.constraint.scale,
                       maxiter=self.iterations)
        return y

    def land(self) -> np.ndarray:
        """The change that lands the linearized keyframes, or comes closest: the least
        squares solution of ``J d = -r`` of least norm in Q's diagonal metric, by LSMR
        (a miss the window cannot steer is left, not chased with ever larger forces)."""
        scale = 1.0 / np.sqrt(self.Q_diagonal)
        m, k = self.r.size, self.cols.size
        J = spla.LinearOperator((m, k), dtype=float, matvec=lambda z: self._J(scale * z),
                                rmatvec=lambda w: scale * self._JT(w))
        z = spla.lsmr(J, -self.r, atol=CG_RTOL, btol=CG_RTOL, maxiter=self.iterations)[0]
        return scale * z

    def projected(self, g_window) -> np.ndarray:
        """The control cost's Newton step in Q's metric (gradient ``g_window`` on the
        window) projected onto the changes that leave the linearized keyframes where they
        are: the damped step is ``projected / (1 + damping) + land``."""
        gi = self.Q_window.solve(g_window)
        return -gi + self._QiJT(self._solve(self._J(gi)))
