r"""Symplectic Euler, eq. (1), and its exact adjoint, eq. (8).

Forward:  ``v_{n+1} = v_n + dt M^-1 (f(x_n, v_n) + e_n)``,  ``x_{n+1} = x_n + dt v_{n+1}``,
where ``e_n`` is every external force of step n (wander plus controls).

Adjoint (exact): with ``a_x, a_v`` the adjoints of frame n+1 and ``w = a_v + dt a_x``,

    dphi/de_n = mu = dt M^-1 w
    a_v(n)    = w   + (df/dv)^T mu + dphi/dv_n
    a_x(n)    = a_x + (df/dx)^T mu + dphi/dx_n

Only the transposed Jacobian-vector products ``(df/dx)^T mu`` and ``(df/dv)^T mu`` of the
model are used.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..trajectory import Trajectory, check_state


class SymplecticEuler:
    """Explicit symplectic Euler for models with ``forces`` and ``forces_vjp``."""

    name = "symplectic_euler"
    exact_adjoint = True
    optional_tape = True  # simulate(..., tape=False) keeps nothing for the adjoint

    def simulate(self, model, x0, v0, external, dt, *, tape: bool = True) -> Trajectory:
        """Run ``len(external)`` steps; ``external`` is ``(steps, n, dim)``.

        With ``tape=False`` the trajectory keeps no per-step record for :meth:`adjoint`
        (``traj.tape`` is empty): for a value only, the record being most of the memory.
        """
        steps = external.shape[0]
        x = np.empty((steps + 1,) + x0.shape)
        v = np.empty_like(x)
        x[0], v[0] = x0, v0
        inv_m = (1.0 / model.masses)[:, None]
        record = []
        for n in range(steps):
            f, t = model.forces(x[n], v[n])
            if tape:
                record.append(t)
            v[n + 1] = v[n] + dt * inv_m * (f + external[n])
            x[n + 1] = x[n] + dt * v[n + 1]
            check_state(x[n + 1], v[n + 1], n + 1)
        return Trajectory(x, v, dt, record)

    def adjoint(self, model, traj: Trajectory, gx, gv):
        """Back-propagate frame gradients ``gx, gv`` ``(steps+1, n, dim)``.

        Returns ``(g_external (steps, n, dim), g_x0, g_v0)``.
        """
        dt, steps = traj.dt, traj.steps
        if len(traj.tape) != steps:
            raise ValueError("the trajectory has no tape for the adjoint: simulate it with "
                             "tape=True (the default)")
        inv_m = (1.0 / model.masses)[:, None]
        g_ext = np.empty((steps,) + traj.x.shape[1:])
        ax, av = gx[steps].copy(), gv[steps].copy()
        for n in range(steps - 1, -1, -1):
            w = av + dt * ax
            mu = dt * inv_m * w
            g_ext[n] = mu
            jx, jv = model.forces_vjp(traj.x[n], traj.v[n], traj.tape[n], mu)
            ax = ax + jx + gx[n]
            av = w + jv + gv[n]
        return g_ext, ax, av

    @staticmethod
    def step_parameters(model, t: float, dt: float) -> np.ndarray:
        """Nothing in a flock depends on time beyond the stored forces: an empty S."""
        return np.zeros(0)

    def symbolic_step(self, model) -> ca.Function:
        """``(X, V, E, dt, S) -> (X+, V+)`` on ``dim x n`` matrices, all pairs, for exact AD
        (S is empty)."""
        shape = (model.dim, model.n)
        X, V, E = (ca.MX.sym(s, *shape) for s in "XVE")
        dt, S = ca.MX.sym("dt"), ca.MX.sym("S", 0)
        inv_m = ca.DM(np.tile(1.0 / model.masses, (model.dim, 1)))
        v_new = V + dt * inv_m * (model.symbolic_forces(X, V) + E)
        x_new = X + dt * v_new
        return ca.Function("symplectic_euler_step", [X, V, E, dt, S], [x_new, v_new]).expand()
