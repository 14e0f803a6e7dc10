r"""Symplectic Euler, eq. (1), with its exact backward step, eq. (8), and its tangent step.

Forward:  ``v_{n+1} = v_n + dt M^-1 (f(x_n, v_n) + e_n)``,  ``x_{n+1} = x_n + dt v_{n+1}``,
where ``e_n`` is every external force of step n (wander plus controls).

Backward (exact): with ``a_x, a_v`` the cotangents of frame n+1 and ``w = a_v + dt a_x``,

    dphi/de_n = mu = dt M^-1 w
    a_v(n)    = w   + (df/dv)^T mu        (+ dphi/dv_n, added by the backward loop)
    a_x(n)    = a_x + (df/dx)^T mu        (+ dphi/dx_n)

The paper's eq. (8) writes ``M^-1`` outside the force Jacobians' transposes; here it is
applied to ``w`` once, which is the same for equal masses and right for unequal ones.

Tangent (exact): ``dv_{n+1} = dv_n + dt M^-1 ((df/dx) dx_n + (df/dv) dv_n + de_n)``,
``dx_{n+1} = dx_n + dt dv_{n+1}``.

The model supplies ``interactions(x)`` (a flock's neighbour pairs, kept as the step's record)
and the products ``forces_vjp`` and ``forces_jvp`` over them.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..models.base import ForceDerivatives
from ..state import State
from .base import Integrator


class SymplecticEuler(Integrator):
    """Explicit symplectic Euler for models with ``forces``, ``forces_vjp`` and ``forces_jvp``."""

    name = "symplectic_euler"
    requires = ForceDerivatives

    def step(self, model, state, external, n, dt, work=None):
        pairs = model.interactions(state.x)
        f = model.forces(state.x, state.v, n * dt, pairs)
        v1 = state.v + dt * (1.0 / model.masses)[:, None] * (f + external)
        x1 = state.x + dt * v1
        model.check_state(x1, v1, n + 1)
        return State(x1, v1), pairs

    def step_vjp(self, model, start, end, record, n, dt, cotangent, work=None):
        w = cotangent.v + dt * cotangent.x
        mu = dt * (1.0 / model.masses)[:, None] * w
        jx, jv = model.forces_vjp(start.x, start.v, n * dt, record, mu)
        return State(cotangent.x + jx, w + jv), mu

    def step_jvp(self, model, start, end, record, n, dt, tangent, d_external, work=None):
        df = model.forces_jvp(start.x, start.v, n * dt, record, tangent.x, tangent.v)
        dv1 = tangent.v + dt * (1.0 / model.masses)[:, None] * (df + d_external)
        return State(tangent.x + dt * dv1, dv1)

    @staticmethod
    def step_parameters(model, t: float, dt: float, record=None) -> np.ndarray:
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
