r"""Linearized backward Euler, eqs. (10)-(12), and the integrator-swapping adjoint (13)-(15).

Forward step (Baraff-Witkin):  ``A dv = b`` with ``A = M - dt D - dt^2 K``,
``b = dt (f_n + dt K v_n + e_n)``, ``K = df/dx|_n`` (at zero velocity), ``D = df/dv|_n``;
``v_{n+1} = v_n + dv``, ``x_{n+1} = x_n + dt v_{n+1}``.  Forces, Jacobians and colliders are
taken at ``t_n = n dt``.  Constrained components get a prescribed ``dv`` (the filter of the
modified CG): pinned particles end the step at rest, attached ones at their path's next
point.  The model supplies symmetric K and D (as Baraff and Witkin, the position derivative
of spring damping is left out of K) with -K and -D positive semi-definite (the cloth clamps
the destabilising parts of its stiffness: compressed springs' transverse term, contact
curvature), so A is symmetric positive definite for every dt; CG refuses it otherwise.

Adjoint ("adjoint", APPROXIMATE): the exact adjoint of this scheme needs second derivatives
of f (derivatives of K and D), a 3p x 3p x 3p tensor.  Following the paper we use instead
the adjoint of FULL backward Euler, ``v+ = v + dt M^-1 f(x+, v+)``, which is linear in the
adjoint variables.  Its Jacobians belong to the step's end state n+1, so its matrix is the A
the forward pass builds there (recomputed, not stored, to keep memory at O(particles x steps)):

    w   = a_v(n+1) + dt a_x(n+1)
    A^T mu = w            (free components; mu = 0 on pinned and attached ones)
    dphi/de_n = dt mu
    a_v(n) = M mu + dphi/dv_n
    a_x(n) = a_x(n+1) + dt J^T mu + dphi/dx_n,    J = df/dx at n+1 (all of it)

A holds the model's clamped stiffness K (so it stays positive definite), but the position
adjoint needs the true force Jacobian J: with K there the gradient misses the compressed
springs' transverse stiffness every step and does not converge as dt shrinks (measured on
the 5 x 5 contact case: relative error 0.71 at dt 1/60, 0.86 at 1/480, against 0.12 and
0.015 with J).  For smooth forces the two schemes agree through second order in dt, so each
step's adjoint carries an O(dt^3) local error.  Stiff springs (dt sqrt(k/m) not small), fast
changes of stiffness (springs entering buckling or contact within a step), the clamping and
the damping term left out of K make the error larger in practice; for forces linear in x and
v it is exact.
The "exact" gradient route (CasADi reverse mode through :meth:`symbolic_step`) is the
reference that measures this error.

``adjoint="exact"`` instead gives the exact adjoint of the linearized scheme by hand
(:meth:`_exact_adjoint`): the same solve with A per step plus per-spring contractions of
the force laws' second and third derivatives, so it costs little more than the swapped one
and, unlike CasADi's unrolled graph, fits any cloth size.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..trajectory import SimulationError, Trajectory, check_state
from .linear_solvers import SOLVERS, SolveError, solve_step

ADJOINTS = ("swapped", "exact")


def step_matrices(model, x, v, dt, t=0.0, with_df_dx=False):
    """``(A, K)`` of an implicit step linearized at (x, v) at time t, both sparse ``3n x 3n``,
    ``A = M - dt D - dt^2 K``; with ``with_df_dx`` also the full force Jacobian ``df/dx``
    (unclamped, damping included)."""
    K, D, *df_dx = model.jacobians(x, v, t, with_df_dx=with_df_dx)
    mass = np.repeat(model.masses, model.dim)
    return ((sp.diags(mass) - dt * D - dt * dt * K).tocsr(), K, *df_dx)


def prescribed_velocity_symbolic(model, X, targets, dt):
    """``d x n`` end-of-step velocities of the constrained particles (SX): zero for pinned
    ones, ``(target - x) / dt`` for attached ones, ``targets`` the flat attachment targets
    (:meth:`model.attachment_targets`); zero for free particles (unused)."""
    v = ca.SX.zeros(model.dim, model.n)
    at = 0
    for a in model.attachments:
        k, idx = a.particles.size, a.particles.tolist()
        v[:, idx] = (ca.reshape(targets[at:at + 3 * k], 3, k) - X[:, idx]) / dt
        at += 3 * k
    return v


def check_stretch(model, x, step: int, limit: float = 5.0) -> None:
    """A spring stretched ``limit`` times its rest length means the step has blown up."""
    stretch = model.max_stretch(x) if hasattr(model, "max_stretch") else 0.0
    if stretch > limit:
        raise SimulationError(
            f"cloth blew up at step {step}: a spring is {stretch:.3g} times its rest length; "
            "reduce dt, the contact stiffness or the speed of moving colliders, or bound "
            "the controls", step)


class LinearizedBackwardEuler:
    """Linearized implicit Euler for models with ``forces`` and sparse ``jacobians``.

    ``tol`` is CG's relative tolerance for the steps, ``adjoint_tol`` for the adjoint's
    solves: a gradient needs fewer digits than a trajectory (1e-8 changes the 20 x 20
    benchmark gradient by 5e-8 relative and saves 15 % of the adjoint's time; the swapped
    adjoint's own error is 1e-2 to 1e-1).
    """

    name = "linearized_backward_euler"

    def __init__(self, solver: str = "cg", tol: float = 1e-10, adjoint: str = "swapped",
                 adjoint_tol: float = 1e-8):
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {sorted(SOLVERS)}, got {solver!r}")
        if adjoint not in ADJOINTS:
            raise ValueError(f"adjoint must be one of {ADJOINTS}, got {adjoint!r}")
        self.solver, self.tol, self.adjoint_kind = solver, tol, adjoint
        self.adjoint_tol = adjoint_tol

    @property
    def exact_adjoint(self) -> bool:
        return self.adjoint_kind == "exact"

    def _solve(self, A, b, free, z=None, x0=None, tol=None):
        return solve_step(self.solver, A, b, free, z, tol=tol or self.tol, x0=x0)

    def simulate(self, model, x0, v0, external, dt) -> Trajectory:
        steps = external.shape[0]
        x = np.empty((steps + 1,) + x0.shape)
        v = np.empty_like(x)
        x[0], v[0] = x0, v0
        dv = None
        for n in range(steps):
            x[n + 1], v[n + 1], dv = self.step(model, x[n], v[n], external[n], n, dt, dv)
        return Trajectory(x, v, dt)

    def step(self, model, x, v, external, n: int, dt: float, dv_guess=None):
        """Step ``n`` (from t = n dt) under the external force ``external`` (``(n, 3)``):
        ``(x+, v+, dv)``, ``dv`` flat (a warm start for the next step's CG).  Raises
        SimulationError if the solve fails, the state is not finite or the cloth blows up."""
        t = n * dt
        A, K = step_matrices(model, x, v, dt, t)
        b = dt * ((model.forces(x, v, t) + external).ravel() + dt * (K @ v.ravel()))
        z = (model.prescribed_velocity(x, t, dt) - v).ravel()
        try:
            dv = self._solve(A, b, model.free_mask(), z, x0=dv_guess)
        except SolveError as err:
            raise SimulationError(f"step {n + 1}: {err}", n + 1) from err
        v1 = v + dv.reshape(v.shape)
        x1 = x + dt * v1
        check_state(x1, v1, n + 1)
        check_stretch(model, x1, n + 1)
        return x1, v1, dv

    @staticmethod
    def force_for(model, x, v, v1, n: int, dt: float) -> np.ndarray:
        """The inverse step: the external force ``(n, 3)`` under which :meth:`step` from
        ``(x, v)`` at step ``n`` ends with velocities ``v1`` (so positions ``x + dt v1``).
        Exact for the free particles; the constrained ones follow their prescribed motion
        whatever the force (and ``v1`` there is ignored), so their force has no effect."""
        t = n * dt
        A, K = step_matrices(model, x, v, dt, t)
        prescribed = model.prescribed_velocity(x, t, dt)
        dv = np.where(model.free_mask(), (v1 - v).ravel(), (prescribed - v).ravel())
        return (A @ dv / dt - dt * (K @ v.ravel())).reshape(v.shape) - model.forces(x, v, t)

    def adjoint(self, model, traj: Trajectory, gx, gv):
        """The adjoint chosen at construction; returns ``(g_external, g_x0, g_v0)``.

        Pinned and attached particles follow prescribed motion, which no control changes:
        their adjoints are dropped, and their parts of ``g_x0, g_v0`` are zero.
        """
        if self.adjoint_kind == "exact":
            return self._exact_adjoint(model, traj, gx, gv)
        return self._swapped_adjoint(model, traj, gx, gv)

    def _swapped_adjoint(self, model, traj: Trajectory, gx, gv):
        """The integrator-swapping adjoint (13)-(15): approximate."""
        dt, steps = traj.dt, traj.steps
        free = model.free_mask().astype(float)
        mass = np.repeat(model.masses, model.dim)
        shape = traj.x.shape[1:]
        g_ext = np.empty((steps,) + shape)
        ax, av = free * gx[steps].ravel(), free * gv[steps].ravel()
        mu = None
        for n in range(steps - 1, -1, -1):
            A, _, df_dx = step_matrices(model, traj.x[n + 1], traj.v[n + 1], dt, (n + 1) * dt,
                                        with_df_dx=True)
            mu = self._solve(A, av + dt * ax, free > 0, x0=mu, tol=self.adjoint_tol)  # A^T = A
            g_ext[n] = (dt * mu).reshape(shape)
            ax = free * (ax + dt * (df_dx.T @ mu) + gx[n].ravel())
            av = free * (mass * mu + gv[n].ravel())
        return g_ext, ax.reshape(shape), av.reshape(shape)

    def _exact_adjoint(self, model, traj: Trajectory, gx, gv):
        """The exact adjoint of the linearized scheme, at about the swapped adjoint's cost.

        Step n solves ``R = b(x, v, e) - A(x, v) dv = 0``.  With ``w = a_v + dt a_x`` (the
        adjoint of dv) and ``A^T lam = w`` (A of step n, as the forward pass built it):
        ``dphi/de_n = dt lam``, ``a_x(n) = a_x + d_x[lam . R]``, ``a_v(n) = w + d_v[lam . R]``.
        The second derivatives hidden in ``d_x[lam . (dt^2 K (v + dv) + dt D dv)]`` are
        contracted per spring by the model (:meth:`linearization_vjp`): the paper's
        3p x 3p x 3p tensors are never formed.  Needs ``model.linearization_vjp``.
        """
        dt, steps = traj.dt, traj.steps
        free = model.free_mask().astype(float)
        shape = traj.x.shape[1:]
        g_ext = np.empty((steps,) + shape)
        ax, av = free * gx[steps].ravel(), free * gv[steps].ravel()
        lam = None
        for n in range(steps - 1, -1, -1):
            t = n * dt
            A, K = step_matrices(model, traj.x[n], traj.v[n], dt, t)
            w = av + dt * ax
            lam = self._solve(A, w, free > 0, x0=lam, tol=self.adjoint_tol)  # A^T = A
            g_ext[n] = (dt * lam).reshape(shape)
            bx, bv = model.linearization_vjp(traj.x[n], traj.v[n], t, lam.reshape(shape),
                                             traj.v[n + 1], traj.v[n + 1] - traj.v[n], dt)
            ax = free * (ax + bx.ravel() + gx[n].ravel())
            av = free * (w + bv.ravel() + dt * dt * (K.T @ lam) + gv[n].ravel())
        return g_ext, ax.reshape(shape), av.reshape(shape)

    @staticmethod
    def step_parameters(model, t: float, dt: float) -> np.ndarray:
        """The symbolic step's S at time t: the scene then, attachment targets at t + dt."""
        return np.concatenate([model.scene_parameters(t), model.attachment_targets(t + dt)])

    def symbolic_step(self, model) -> ca.Function:
        """``(X, V, E, dt, S) -> (X+, V+)``: the linearized step in CasADi, for exact reverse
        mode; S from :meth:`step_parameters`.

        K and D come from the model's :meth:`symbolic_jacobians` (the same kernels as the
        numeric step), so second derivatives of the forces enter through them; the linear
        solve is differentiated exactly (``ldl``).  For small systems only.
        """
        n, d = model.n, model.dim
        n_scene = model.scene_parameters(0.0).size
        n_s = n_scene + model.attachment_targets(0.0).size
        X, V, E = (ca.SX.sym(s, d, n) for s in "XVE")
        dt, S = ca.SX.sym("dt"), ca.SX.sym("S", n_s)
        scene = S[:n_scene]
        f = ca.vec(model.symbolic_forces(X, V, scene))
        K, D = model.symbolic_jacobians(X, V, scene)
        mass = np.repeat(model.masses, d)
        A = ca.diag(ca.DM(mass)) - dt * D - dt * dt * K
        b = dt * (f + ca.vec(E) + dt * ca.mtimes(K, ca.vec(V)))
        v_new = prescribed_velocity_symbolic(model, X, S[n_scene:], dt)
        system = ca.Function("lbe_system", [X, V, E, dt, S], [A, b, ca.vec(v_new - V)])
        Xm, Vm, Em = (ca.MX.sym(s, d, n) for s in "XVE")
        dtm, Sm = ca.MX.sym("dt"), ca.MX.sym("S", n_s)
        Am, bm, dvm = system(Xm, Vm, Em, dtm, Sm)
        free = model.free_mask()
        fi, ci = np.flatnonzero(free).tolist(), np.flatnonzero(~free).tolist()
        dv = dvm
        rhs = bm[fi] - (ca.mtimes(Am[fi, ci], dvm[ci]) if ci else 0)
        dv[fi] = ca.solve(Am[fi, fi], rhs, "ldl")
        v_next = Vm + ca.reshape(dv, d, n)
        return ca.Function("lbe_step", [Xm, Vm, Em, dtm, Sm], [Xm + dtm * v_next, v_next])
