"""Gravity and air drag as a family: ``m_i g - air_drag m_i v_i`` on every particle.

Drag is proportional to the mass, so its deceleration does not depend on the resolution.
Both are linear (drag in v, gravity constant), so the family's Jacobian is the diagonal
``D = -air_drag m_i I``, its second derivatives vanish, and everything is plain numpy.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .interaction import FamilyBlocks, Interaction


class GravityAndDrag(Interaction):
    """``m_i g - air_drag m_i v_i`` for particles of ``masses`` (kg), ``gravity`` (m/s^2)."""

    name = "gravity and drag"

    def __init__(self, masses: np.ndarray, gravity, air_drag: float):
        self.masses, self.air_drag = masses, float(air_drag)
        self.gravity = masses[:, None] * np.asarray(gravity, dtype=float)[None, :]
        self.damping_blocks = np.outer(-self.air_drag * masses, np.eye(3).ravel())
        for a in (self.gravity, self.damping_blocks):
            a.flags.writeable = False

    def _drag(self, v):
        return self.air_drag * self.masses[:, None] * np.asarray(v, dtype=float)

    def forces(self, x, v, t, found):
        return self.gravity - self._drag(v)

    def add_forces(self, out, x, v, t, found):
        out += self.gravity
        out -= self._drag(v)

    def blocks(self, x, v, t, kinds, found):
        parts = {"jac": (None, self.damping_blocks), "df_dx": (None,)}
        return FamilyBlocks(particles=tuple(b for k in kinds for b in parts[k]))

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        return None, -(dt * self.air_drag * (self.masses[:, None] * lam))

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        return -(dt * self.air_drag * (self.masses[:, None] * dv))

    def symbolic_forces(self, X, V, S, decisions=None):
        mass = ca.repmat(ca.DM(self.masses).T, 3, 1)
        return ca.DM(self.gravity.T) - self.air_drag * V * mass

    def symbolic_blocks(self, X, V, S, decisions=None):
        return FamilyBlocks(particles=(None, ca.DM(np.asarray(self.damping_blocks).T)))

    def step_jacobian(self, x, v, w, q, times, dt):
        """Drag only: ``-dt drag m`` in v and in q (gravity is constant)."""
        steps, n = x.shape[:2]
        blocks = np.zeros((steps, n, 4, 3, 3))
        block = -dt * self.air_drag * self.masses[:, None, None] * np.eye(3)
        blocks[:, :, 1] = blocks[:, :, 3] = block
        return np.arange(n)[:, None], blocks

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        drag = self.air_drag * ca.repmat(ca.DM(self.masses).T, 3, 1)
        return dt * (ca.DM(self.gravity.T) - drag * V) - dt * drag * Q
