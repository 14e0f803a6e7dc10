r"""Full backward Euler, eq. (9): the nonlinear implicit step solved by Newton's method.

Step from (x, v) at time t to t+ = t + dt: find v+ with

    R(v+) = M (v+ - v) - dt (f(x + dt v+, v+, t+) + e) = 0,     x+ = x + dt v+

on the free components (pinned and attached ones take their prescribed velocity, as in
:mod:`.linearized_backward_euler`).  With ``solver="direct"`` (default) Newton's iteration
uses the true Jacobian of R (sparse LU): 5-7 iterations to 1e-10 on a 4 x 4 sheet in contact.
With ``"cg"`` it uses the step matrix ``A = M - dt D - dt^2 K`` of the model's symmetric,
clamped stiffness, positive definite so CG applies; the residual is the true one, so it
converges to the same step, but linearly (14-26 iterations on the same sheet: contact
damping's position derivative and the clamping are missing from A).  The linearized scheme
is the first Newton iterate from ``v+ = v`` with the Jacobians at the start of the step,
which is why the two differ by O(dt^3) per step for smooth forces.

Adjoint: the swapped adjoint of the linearized scheme IS the exact adjoint here, once it uses
the true Jacobians at the step's end, ``J = df/dx`` and ``D = df/dv`` at (x+, v+, t+):

    w = a_v(n+1) + dt a_x(n+1)
    (M - dt D - dt^2 J)^T lam = w          (free components; sparse LU, J is not symmetric)
    dphi/de_n = dt lam,   a_v(n) = M lam + dphi/dv_n,   a_x(n) = a_x(n+1) + dt J^T lam + dphi/dx_n

exact up to the Newton tolerance.  The "exact" gradient route differentiates CasADi's Newton
rootfinder on the same residual (implicit function theorem) and checks it.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..trajectory import SimulationError, Trajectory, check_state
from .linear_solvers import SOLVERS, SolveError, direct_solve, solve_step
from .linearized_backward_euler import (check_stretch, prescribed_velocity_symbolic,
                                        step_matrices)


def residual_jacobian(model, xp, vp, t, dt, mass):
    """``(dR/dv+, df/dx)`` at the end state (xp, vp) at time t: ``M - dt D - dt^2 df/dx``
    with the true, unclamped Jacobians (not symmetric), and df/dx itself."""
    _, D, df_dx = model.jacobians(xp, vp, t, with_df_dx=True)
    return sp.diags(mass) - dt * D - dt * dt * df_dx, df_dx


class BackwardEuler:
    """Backward Euler for models with ``forces`` and sparse ``jacobians`` (cloth).

    ``solver`` ("direct" or "cg", see the module docstring) solves each Newton system (CG to
    ``tol``); Newton stops when its update is below ``newton_tol`` (m/s, relative to
    ``max(1, |v+|)``) and reports a :class:`SimulationError` after ``max_newton`` iterations.
    """

    name = "backward_euler"
    exact_adjoint = True

    def __init__(self, solver: str = "direct", tol: float = 1e-12, newton_tol: float = 1e-10,
                 max_newton: int = 50):
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {sorted(SOLVERS)}, got {solver!r}")
        if not (0 < newton_tol < 1) or int(max_newton) < 1:
            raise ValueError("newton_tol must be in (0, 1) and max_newton at least 1, got "
                             f"{newton_tol}, {max_newton}")
        self.solver, self.tol = solver, tol
        self.newton_tol, self.max_newton = newton_tol, int(max_newton)
        self.newton_iterations: list[int] = []

    def simulate(self, model, x0, v0, external, dt) -> Trajectory:
        steps = external.shape[0]
        x = np.empty((steps + 1,) + x0.shape)
        v = np.empty_like(x)
        x[0], v[0] = x0, v0
        free = model.free_mask()
        self.newton_iterations = []
        for n in range(steps):
            v[n + 1] = self._newton(model, x[n], v[n], external[n], n * dt, dt, free, n + 1)
            x[n + 1] = x[n] + dt * v[n + 1]
            check_state(x[n + 1], v[n + 1], n + 1)
            check_stretch(model, x[n + 1], n + 1)
        return Trajectory(x, v, dt)

    def _newton(self, model, x, v, e, t, dt, free, step: int) -> np.ndarray:
        """v+ of one step; the constrained components take their prescribed velocity."""
        mass = np.repeat(model.masses, model.dim)
        vp = np.where(free.reshape(v.shape), v, model.prescribed_velocity(x, t, dt))
        delta = None
        for it in range(1, self.max_newton + 1):
            xp = x + dt * vp
            residual = mass * (vp - v).ravel() - dt * (model.forces(xp, vp, t + dt) + e).ravel()
            try:
                delta = self._newton_step(model, xp, vp, t + dt, dt, mass, -residual, free)
            except SolveError as err:
                raise SimulationError(f"step {step}: {err}", step) from err
            vp = vp + delta.reshape(vp.shape)
            if not np.all(np.isfinite(vp)):
                break
            if np.abs(delta).max() <= self.newton_tol * max(1.0, np.abs(vp).max()):
                self.newton_iterations.append(it)
                return vp
        raise SimulationError(
            f"step {step}: Newton's method did not converge in {self.max_newton} iterations "
            f"(last update {np.abs(delta).max():.2e} m/s); reduce dt or the stiffness", step)

    def _newton_step(self, model, xp, vp, t, dt, mass, rhs, free):
        """Newton update: with "direct", the true Jacobian of the residual (sparse LU,
        quadratic convergence); with "cg", the symmetric positive definite step matrix of
        the clamped stiffness (CG applies; linear convergence where clamping or damping's
        position derivative matter)."""
        if self.solver == "direct":
            jacobian, _ = residual_jacobian(model, xp, vp, t, dt, mass)
            return direct_solve(jacobian.tocsr(), rhs, free, symmetric=False)[0]
        A, _ = step_matrices(model, xp, vp, dt, t)
        return solve_step(self.solver, A, rhs, free, np.zeros_like(rhs), tol=self.tol)

    def adjoint(self, model, traj: Trajectory, gx, gv):
        """The exact adjoint of backward Euler; returns ``(g_external, g_x0, g_v0)``."""
        dt, steps = traj.dt, traj.steps
        free_mask = model.free_mask()
        free = free_mask.astype(float)
        mass = np.repeat(model.masses, model.dim)
        shape = traj.x.shape[1:]
        g_ext = np.empty((steps,) + shape)
        ax, av = free * gx[steps].ravel(), free * gv[steps].ravel()
        for n in range(steps - 1, -1, -1):
            t1 = (n + 1) * dt
            jacobian, df_dx = residual_jacobian(model, traj.x[n + 1], traj.v[n + 1], t1, dt, mass)
            try:
                lam = direct_solve(jacobian.T.tocsr(), av + dt * ax, free_mask, symmetric=False)[0]
            except SolveError as err:
                raise SimulationError(f"adjoint of step {n + 1}: {err}", n + 1) from err
            g_ext[n] = (dt * lam).reshape(shape)
            ax = free * (ax + dt * (df_dx.T @ lam) + gx[n].ravel())
            av = free * (mass * lam + gv[n].ravel())
        return g_ext, ax.reshape(shape), av.reshape(shape)

    @staticmethod
    def step_parameters(model, t: float, dt: float) -> np.ndarray:
        """The symbolic step's S for the step from t: the scene and attachments at t + dt."""
        return np.concatenate([model.scene_parameters(t + dt), model.attachment_targets(t + dt)])

    def symbolic_step(self, model) -> ca.Function:
        """``(X, V, E, dt, S) -> (X+, V+)``: CasADi's Newton rootfinder on the step's residual,
        differentiated by the implicit function theorem (exact); for small systems."""
        n, d = model.n, model.dim
        n_scene = model.scene_parameters(0.0).size
        n_s = n_scene + model.attachment_targets(0.0).size
        Vp, X, V, E = (ca.SX.sym(s, d, n) for s in ("Vp", "X", "V", "E"))
        dt, S = ca.SX.sym("dt"), ca.SX.sym("S", n_s)
        f = model.symbolic_forces(X + dt * Vp, Vp, S[:n_scene])
        mass = ca.repmat(ca.DM(model.masses).T, d, 1)
        residual = mass * (Vp - V) - dt * (f + E)
        target = prescribed_velocity_symbolic(model, X, S[n_scene:], dt)
        free = ca.DM(model.free_mask().reshape(n, d).T.astype(float))
        residual = free * residual + (1 - free) * (Vp - target)
        G = ca.Function("be_residual", [ca.vec(Vp), X, V, E, dt, S], [ca.vec(residual)])
        root = ca.rootfinder("be_newton", "newton", G,
                             {"abstol": 1e-13, "abstolStep": 1e-14, "max_iter": 100,
                              "error_on_fail": True})
        Xm, Vm, Em = (ca.MX.sym(s, d, n) for s in "XVE")
        dtm, Sm = ca.MX.sym("dt"), ca.MX.sym("S", n_s)
        v_next = ca.reshape(root(ca.vec(Vm), Xm, Vm, Em, dtm, Sm), d, n)
        return ca.Function("be_step", [Xm, Vm, Em, dtm, Sm], [Xm + dtm * v_next, v_next])
