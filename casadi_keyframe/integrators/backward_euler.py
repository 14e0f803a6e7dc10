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

Backward step (exact): the swapped adjoint of the linearized scheme IS the exact adjoint
here, once it uses the true Jacobians at the step's end, ``J = df/dx`` and ``D = df/dv`` at
(x+, v+, t+):

    w = a_v(n+1) + dt a_x(n+1)
    (M - dt D - dt^2 J)^T lam = w          (free components; sparse LU, J is not symmetric)
    dphi/de_n = dt lam,   a_v(n) = M lam + dphi/dv_n,   a_x(n) = a_x(n+1) + dt J^T lam + dphi/dx_n

exact up to the Newton tolerance.  Tangent step (exact): the same matrix, forward,

    (M - dt D - dt^2 J) dv+ = M dv + dt J dx + dt de,     dx+ = dx + dt dv+

The "casadi" gradient route differentiates CasADi's Newton rootfinder on the same residual
(implicit function theorem) and checks both.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..linear import ModifiedPCG, SolveError, SolveInfo, SparseLU
from ..models.base import ForceJacobians, StepHold
from ..state import SimulationError, State
from .base import Integrator, Workspace, free_components, mass_diagonal
from .linearized_backward_euler import step_matrices


def residual_jacobian(model, xp, vp, t, dt, interactions=None):
    """``(dR/dv+, df/dx)`` at the end state (xp, vp) at time t: ``M - dt D - dt^2 df/dx``
    with the true, unclamped Jacobians (not symmetric), and df/dx itself."""
    _, D, df_dx = model.jacobians(xp, vp, t, with_df_dx=True, interactions=interactions)
    return sp.diags(mass_diagonal(model)) - dt * D - dt * dt * df_dx, df_dx


@dataclass(frozen=True)
class NewtonStep:
    """What a backward Euler step keeps: Newton's iteration count and its linear solves."""

    iterations: int
    solves: tuple[SolveInfo, ...]


NEWTON_SOLVERS = ("direct", "cg")  # the true (non-symmetric) Jacobian, or the SPD step matrix


class BackwardEuler(Integrator):
    """Backward Euler for models with ``forces`` and sparse ``jacobians`` (cloth).

    ``solver`` ("direct" or "cg", see the module docstring) solves each Newton system (CG to
    ``tol``); Newton stops when its update is below ``newton_tol`` (m/s, relative to
    ``max(1, |v+|)``) and reports a :class:`SimulationError` after ``max_newton`` iterations.
    The backward and tangent steps use sparse LU on the true Jacobian whatever ``solver``.
    """

    name = "backward_euler"
    requires = ForceJacobians

    def __init__(self, solver: str = "direct", tol: float = 1e-12, newton_tol: float = 1e-10,
                 max_newton: int = 50):
        if solver not in NEWTON_SOLVERS:
            raise ValueError(f"solver must be one of {sorted(NEWTON_SOLVERS)}, got {solver!r}")
        if not (0 < newton_tol < 1) or int(max_newton) < 1:
            raise ValueError("newton_tol must be in (0, 1) and max_newton at least 1, got "
                             f"{newton_tol}, {max_newton}")
        self.solver, self.tol = solver, tol
        self.newton_solver = ModifiedPCG(tol) if solver == "cg" else SparseLU(symmetric=False)
        self.jacobian_solver = SparseLU(symmetric=False)
        self.newton_tol, self.max_newton = newton_tol, int(max_newton)

    def check_model(self, model) -> None:
        """As every scheme's, and contact must be the paper's penalty springs: a step that
        holds particles (``collision="guarded"`` or ``"constraint"``) is the linearized
        scheme's."""
        super().check_model(model)
        if isinstance(model, StepHold) and model.holding:
            raise ValueError("full backward Euler steps penalty contact only: build the cloth "
                             "with collision='penalty', or step it with "
                             "LinearizedBackwardEuler, which holds particles on bodies")

    def init(self, model) -> Workspace:
        self.check_model(model)
        return Workspace(self.jacobian_solver.init(model.free_mask()))

    def step(self, model, state, external, n, dt, work=None):
        """v+ of one step by Newton's method; the constrained components take their
        prescribed velocity."""
        x, v, t, step = state.x, state.v, n * dt, n + 1
        free = model.free_mask()
        plan = self.newton_solver.init(free)
        mass = mass_diagonal(model)
        vp = np.where(free.reshape(v.shape), v, model.prescribed_velocity(x, t, dt))
        delta, solves = None, []
        for it in range(1, self.max_newton + 1):
            xp = x + dt * vp
            contacts = model.interactions(xp)
            residual = mass * (vp - v).ravel() - dt * (model.forces(xp, vp, t + dt, contacts)
                                                       + external).ravel()
            try:
                delta, info = self._newton_step(model, xp, vp, t + dt, dt, -residual, plan,
                                                contacts)
            except SolveError as err:
                raise SimulationError(f"step {step}: {err}", step) from err
            solves.append(info)
            vp = vp + delta.reshape(vp.shape)
            if not np.all(np.isfinite(vp)):
                break
            if np.abs(delta).max() <= self.newton_tol * max(1.0, np.abs(vp).max()):
                x1 = x + dt * vp
                model.check_state(x1, vp, step)
                return State(x1, vp), NewtonStep(it, tuple(solves))
        raise SimulationError(
            f"step {step}: Newton's method did not converge in {self.max_newton} iterations "
            f"(last update {np.abs(delta).max():.2e} m/s); reduce dt or the stiffness", step)

    def _newton_step(self, model, xp, vp, t, dt, rhs, plan, contacts):
        """Newton update: with "direct", the true Jacobian of the residual (sparse LU,
        quadratic convergence); with "cg", the symmetric positive definite step matrix of
        the clamped stiffness (CG applies; linear convergence where clamping or damping's
        position derivative matter)."""
        if self.solver == "direct":
            jacobian, _ = residual_jacobian(model, xp, vp, t, dt, contacts)
            return plan.factor(jacobian).solve(rhs)
        A, _ = step_matrices(model, xp, vp, dt, t, interactions=contacts)
        return plan.factor(A).solve(rhs, np.zeros_like(rhs))

    def _end_jacobian(self, model, end, n, dt, work):
        """The factored ``M - dt D - dt^2 J`` and ``J`` at the step's end state."""
        jacobian, df_dx = residual_jacobian(model, end.x, end.v, (n + 1) * dt, dt)
        try:
            return work.factor(jacobian.tocsr()), df_dx
        except SolveError as err:
            raise SimulationError(f"derivative of step {n + 1}: {err}", n + 1) from err

    def step_vjp(self, model, start, end, record, n, dt, cotangent, work=None):
        """The exact backward step of backward Euler (module docstring)."""
        work = self.init(model) if work is None else work
        shape = start.x.shape
        free = free_components(model, shape).ravel()
        ax, av = free * cotangent.x.ravel(), free * cotangent.v.ravel()
        system, df_dx = self._end_jacobian(model, end, n, dt, work)
        lam, _ = system.solve_transpose(av + dt * ax)
        ax = free * (ax + dt * (df_dx.T @ lam))
        av = free * (mass_diagonal(model) * lam)
        return State(ax.reshape(shape), av.reshape(shape)), (dt * lam).reshape(shape)

    def step_jvp(self, model, start, end, record, n, dt, tangent, d_external, work=None):
        """The exact tangent step of backward Euler (module docstring)."""
        work = self.init(model) if work is None else work
        shape = start.x.shape
        free = free_components(model, shape).ravel()
        dx, dv = free * tangent.x.ravel(), free * tangent.v.ravel()
        system, df_dx = self._end_jacobian(model, end, n, dt, work)
        rhs = mass_diagonal(model) * dv + dt * (df_dx @ dx) + dt * np.asarray(d_external).ravel()
        dv1, _ = system.solve(rhs)
        dv1 = free * dv1
        return State((free * (dx + dt * dv1)).reshape(shape), dv1.reshape(shape))

    @staticmethod
    def step_parameters(model, t: float, dt: float, record=None) -> np.ndarray:
        """The symbolic step's S for the step from t: the scene and attachments at t + dt."""
        return np.concatenate([model.scene_parameters(t + dt), model.constraint_targets(t + dt)])

    def symbolic_step(self, model) -> ca.Function:
        """``(X, V, E, dt, S) -> (X+, V+)``: CasADi's Newton rootfinder on the step's residual,
        differentiated by the implicit function theorem (exact); for small systems."""
        n, d = model.n, model.dim
        n_scene = model.scene_parameters(0.0).size
        n_s = n_scene + model.constraint_targets(0.0).size
        Vp, X, V, E = (ca.SX.sym(s, d, n) for s in ("Vp", "X", "V", "E"))
        dt, S = ca.SX.sym("dt"), ca.SX.sym("S", n_s)
        f = model.symbolic_forces(X + dt * Vp, Vp, S[:n_scene])
        mass = ca.repmat(ca.DM(model.masses).T, d, 1)
        residual = mass * (Vp - V) - dt * (f + E)
        target = model.prescribed_velocity_symbolic(X, S[n_scene:], dt)
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
