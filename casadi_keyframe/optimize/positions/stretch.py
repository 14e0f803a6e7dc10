r"""The physical stretch limit in positions, as constraints: every spring with a free end, at
every frame 1..N,

    s(z) = |x_j - x_i|^2 / rest^2 <= (margin limit)^2,

``limit`` the problem's :class:`~...objectives.tolerances.PhysicalLimits` stretch (a result
whose spring passes it is torn, not converged).  Each is quadratic in two particles'
positions: its gradient is exact and cheap, its Hessian ``(2 / rest^2) [[I, -I], [-I, I]]``
constant, so an interior-point search holds thousands of them at the price of a sparse
Jacobian (:mod:`.interior`)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

STRETCH_MARGIN = 0.99  # a spring is held within this share of the physical limit


class StretchLimit:
    """The constraints of the module docstring on a transcription ``tr``; ``bound`` is the
    squared limit each value is held below."""

    def __init__(self, tr, limit: float, margin: float = STRETCH_MARGIN):
        springs = tr.problem.model.springs
        column = np.full(3 * tr.n, -1)
        column[tr.free_flat] = np.arange(tr.nf)
        free = (column.reshape(-1, 3) >= 0).any(axis=1)
        keep = free[springs.i] | free[springs.j]
        self.tr, self.i, self.j = tr, springs.i[keep], springs.j[keep]
        self.rest = springs.rest[keep]
        self.bound = (margin * limit) ** 2
        count = self.i.size
        self.size = count * tr.N
        frame = np.repeat(np.arange(tr.N), count)
        spring = np.tile(np.arange(count), tr.N)
        offset = (frame * tr.nf)[:, None]
        ends = [column[3 * end[spring][:, None] + np.arange(3)] for end in (self.i, self.j)]
        row = np.repeat(np.arange(self.size), 3)
        self._rows = np.concatenate([row, row])
        self._cols = np.concatenate([(offset + e).ravel() for e in ends])
        self._valid = np.concatenate([e.ravel() >= 0 for e in ends])
        self._inverse_rest2 = np.tile(1.0 / self.rest ** 2, tr.N)

    def _differences(self, z) -> np.ndarray:
        x = self.tr.frames(z)[1:]
        return x[:, self.j] - x[:, self.i]  # (N, springs, 3)

    def values(self, z) -> np.ndarray:
        """Each spring's squared stretch at each frame (frame-major)."""
        return np.sum(self._differences(z) ** 2, axis=-1).ravel() * self._inverse_rest2

    def jacobian(self, z) -> sp.csr_matrix:
        """``d values / dz``: six entries per row, fewer where an end is prescribed."""
        d = (2.0 * self._differences(z).reshape(-1, 3) * self._inverse_rest2[:, None]).ravel()
        v = self._valid
        return sp.csr_matrix((np.concatenate([-d, d])[v], (self._rows[v], self._cols[v])),
                             shape=(self.size, self.tr.size))

    def hessian(self, lam) -> sp.csr_matrix:
        """``sum_k lam_k d^2 values_k / dz^2`` (exact, constant in z)."""
        w = np.repeat(2.0 * np.asarray(lam) * self._inverse_rest2, 3)
        half = w.size
        ci, cj = self._cols[:half], self._cols[half:]
        vi, vj = self._valid[:half], self._valid[half:]
        both = vi & vj
        rows = np.concatenate([ci[vi], cj[vj], ci[both], cj[both]])
        cols = np.concatenate([ci[vi], cj[vj], cj[both], ci[both]])
        vals = np.concatenate([w[vi], w[vj], -w[both], -w[both]])
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.tr.size,) * 2)

    def stretch(self, z) -> float:
        """The largest stretch (length over rest length) of these springs along ``z``."""
        return float(np.sqrt(self.values(z).max(initial=0.0)))
