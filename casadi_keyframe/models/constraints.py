"""Particles whose motion is prescribed: pinned ones stay put, attached ones follow a path (a
hand, a shoulder).  The numeric and symbolic forms sit side by side, so the step and the
CasADi reference prescribe the same velocities.

An implicit step holds these components fixed in its linear solve (the filter of
Baraff and Witkin's modified CG); every derivative step drops their tangents and cotangents.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np


@dataclass(frozen=True)
class Attachment:
    """Particles led along a path: ``path(t)`` gives their ``(k, 3)`` positions at time t (s).

    The integrator sets their velocity each step so they reach ``path(t + dt)`` exactly.
    """

    particles: np.ndarray
    path: object

    def __post_init__(self):
        idx = np.atleast_1d(np.asarray(self.particles))
        if idx.dtype.kind not in "iu" or idx.size == 0:
            raise ValueError("Attachment particles must be a non-empty list of indices")
        object.__setattr__(self, "particles", idx.astype(np.intp))
        if not callable(self.path):
            raise ValueError("Attachment path must be a function of time t -> (k, 3) positions")
        self.positions(0.0)

    def positions(self, t: float) -> np.ndarray:
        p = np.asarray(self.path(t), dtype=float)
        if p.shape != (self.particles.size, 3) or not np.all(np.isfinite(p)):
            raise ValueError(f"Attachment path(t) must return finite ({self.particles.size}, 3) "
                             f"positions, got shape {p.shape}")
        return p


def check_pinned(pinned, n: int) -> np.ndarray:
    """Sorted unique pinned indices, each in 0..n-1 (ValueError otherwise)."""
    if not np.size(pinned):
        return np.zeros(0, np.intp)
    p = np.unique(np.asarray(pinned, dtype=np.intp).ravel())
    if p.size and (p.min() < 0 or p.max() >= n):
        raise ValueError(f"pinned particle indices must be in 0..{n - 1}, got {p.min()}..{p.max()}")
    return p


class Constraints:
    """The pinned particles and the attachments of a system of ``n`` particles in 3-D."""

    def __init__(self, n: int, pinned=(), attachments=()):
        self.n = n
        self.pinned = check_pinned(pinned, n)
        self.attachments = tuple(attachments)
        for a in self.attachments:
            if not isinstance(a, Attachment):
                raise ValueError(f"attachments must be Attachment objects, got {a!r}")
        constrained = np.concatenate([self.pinned] + [a.particles for a in self.attachments])
        if np.unique(constrained).size != constrained.size:
            raise ValueError("a particle is pinned or attached twice; give each one constraint")
        if constrained.size and (constrained.min() < 0 or constrained.max() >= n):
            raise ValueError(f"attached particle index out of range 0..{n - 1}")
        free = np.ones((n, 3), bool)
        free[constrained.astype(np.intp)] = False
        self.free = free.ravel()
        self.free.flags.writeable = False

    def prescribed_velocity(self, x: np.ndarray, t: float, dt: float) -> np.ndarray:
        """``(n, 3)`` velocities at the end of the step from time t: zero for pinned particles,
        ``(path(t + dt) - x) / dt`` for attached ones (zero for free particles, unused)."""
        out = np.zeros((self.n, 3))
        for a in self.attachments:
            out[a.particles] = (a.positions(t + dt) - x[a.particles]) / dt
        return out

    def targets(self, t: float) -> np.ndarray:
        """Positions of every attached particle at time t, flat (attachment order): the
        symbolic step's inputs for the step that ends at t."""
        return np.concatenate([a.positions(t).ravel() for a in self.attachments]
                              or [np.zeros(0)])

    def prescribed_velocity_symbolic(self, X, targets, dt):
        """:meth:`prescribed_velocity` in CasADi: ``3 x n`` (SX), ``targets`` the flat
        :meth:`targets` at the step's end, zero for free particles (unused)."""
        v = ca.SX.zeros(3, self.n)
        at = 0
        for a in self.attachments:
            k, idx = a.particles.size, a.particles.tolist()
            v[:, idx] = (ca.reshape(targets[at:at + 3 * k], 3, k) - X[:, idx]) / dt
            at += 3 * k
        return v
