"""How the control vector u acts on the system (the paper's C_n).

Every control starts at zero, meaning the passive simulation.  ``u`` is a flat float64
vector; the classes below say how it maps to per-step external forces or to a change of
the initial velocities, how gradients flow back, and give the same map symbolically for the
exact CasADi route.
"""
from __future__ import annotations

import casadi as ca
import numpy as np


class Controls:
    """Base: ``bind`` to a system, then map ``u`` to forces / initial-velocity offsets."""

    def __init__(self, agents=None, *, lower=None, upper=None):
        self.agents, self.lower, self.upper = agents, lower, upper

    def bind(self, n: int, dim: int, steps: int) -> None:
        if self.agents is None:
            self.idx = np.arange(n)
        else:
            self.idx = np.unique(np.atleast_1d(np.asarray(self.agents)))
            if self.idx.dtype.kind not in "iu" or self.idx.size == 0:
                raise ValueError("controlled agents must be a non-empty list of indices")
            if self.idx.min() < 0 or self.idx.max() >= n:
                raise ValueError(f"controlled agent index out of range 0..{n - 1}")
        self.n, self.dim, self.steps = n, dim, steps
        self.bounds()  # validate early

    @property
    def block_shape(self) -> tuple:
        raise NotImplementedError

    @property
    def size(self) -> int:
        return int(np.prod(self.block_shape))

    def zeros(self) -> np.ndarray:
        return np.zeros(self.size)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds on u (``-inf``/``inf`` where unbounded)."""
        lb = np.broadcast_to(-np.inf if self.lower is None else np.asarray(self.lower, float),
                             (self.size,)).copy()
        ub = np.broadcast_to(np.inf if self.upper is None else np.asarray(self.upper, float),
                             (self.size,)).copy()
        if np.any(np.isnan(lb)) or np.any(np.isnan(ub)) or np.any(lb > ub):
            raise ValueError("control bounds must satisfy lower <= upper and contain no NaN")
        if np.any(lb > 0) or np.any(ub < 0):
            raise ValueError("control bounds must contain zero (the passive simulation)")
        return lb, ub

    def check(self, u) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        if u.shape != (self.size,):
            raise ValueError(f"controls must be a flat vector of length {self.size} "
                             f"({' x '.join(map(str, self.block_shape))}), got shape {u.shape}")
        if not np.all(np.isfinite(u)):
            raise ValueError("controls contain NaN or inf")
        return u

    # numeric map and its transpose
    def external(self, u) -> np.ndarray | None:
        """Per-step control forces ``(steps, n, dim)``, or None."""
        return None

    def velocity_offset(self, u) -> np.ndarray | None:
        """Change of the initial velocities ``(n, dim)``, or None."""
        return None

    def pullback(self, g_external, g_v0) -> np.ndarray:
        """d phi / d u from d phi / d(external forces) and d phi / d v0."""
        raise NotImplementedError

    # symbolic map
    def symbolic(self, U):
        """``(list of per-step dim x n forces or None, dim x n velocity offset or None)``."""
        raise NotImplementedError

    def step_blocks(self, U):
        """U as a ``(k*dim, steps)`` matrix, one column per step; None if not per-step."""
        return None

    def _selection(self) -> ca.DM:
        sel = np.zeros((self.idx.size, self.n))
        sel[np.arange(self.idx.size), self.idx] = 1.0
        return ca.sparsify(ca.DM(sel))


class StepForces(Controls):
    """One force per controlled particle per step (the paper's flocking and cloth controls)."""

    label = "per-step forces"

    @property
    def block_shape(self):
        return (self.steps, self.idx.size, self.dim)

    def external(self, u):
        out = np.zeros((self.steps, self.n, self.dim))
        out[:, self.idx] = u.reshape(self.block_shape)
        return out

    def pullback(self, g_external, g_v0):
        return np.ascontiguousarray(g_external[:, self.idx]).ravel()

    def step_blocks(self, U):
        return ca.reshape(U, self.idx.size * self.dim, self.steps)

    def symbolic(self, U):
        blocks = self.step_blocks(U)
        sel = self._selection()
        k = self.idx.size
        forces = [ca.mtimes(ca.reshape(blocks[:, s], self.dim, k), sel) for s in range(self.steps)]
        return forces, None


class InitialVelocity(Controls):
    """Only the initial velocities of the controlled particles (fig. 5: the cloth toss)."""

    label = "initial velocities"

    @property
    def block_shape(self):
        return (self.idx.size, self.dim)

    def velocity_offset(self, u):
        out = np.zeros((self.n, self.dim))
        out[self.idx] = u.reshape(self.block_shape)
        return out

    def pullback(self, g_external, g_v0):
        return np.ascontiguousarray(g_v0[self.idx]).ravel()

    def symbolic(self, U):
        return None, ca.mtimes(ca.reshape(U, self.dim, self.idx.size), self._selection())
