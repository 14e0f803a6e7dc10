r"""The effort's second-order part, which its Gauss-Newton matrix leaves out: with the forces
``u(z)`` and the control cost's gradient ``g = dC/du``, the exact Hessian of the effort is

    J^T Q J + sum_i g_i d^2 u_i / dz^2 + Jr^T Jr + sum_k r_k d^2 r_k / dz^2.

The forces' part is one CasADi Hessian per step of ``<W_n, e_n(x_{n-1}, x_n, x_{n+1})>`` (the
inverse step of :mod:`.transcription`, ``W_n`` the weights ``g`` of step n), mapped over the
steps and gathered; the strain penalty's part is each stretched spring's
``(s / rest) (I - d d^T / |d|^2) / |d|`` on its two ends.  Where the sheet buckles the sum is
indefinite: the Gauss-Newton matrix is the default, this is ``hessian=exact``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .transcription import Buffered, inverse_step_function


def weighted_step_hessian(tr):
    """``(fn, (rows, cols))``: ``fn(X_{n-1}, X_n, X_{n+1}, S, W)`` the Hessian of
    ``<W, e_n>`` in the three frames stacked (``9n`` square, sparse; ``e_n`` the inverse step
    of :mod:`.transcription`) and its pattern's triplets."""
    n = tr.n
    step = inverse_step_function(tr.model, tr.dt).expand()
    frames = [ca.SX.sym(name, 3, n) for name in ("before", "now", "next")]
    scene = ca.SX.sym("scene", tr.scene.shape[0])
    weights = ca.SX.sym("w", 3, n)
    stacked = ca.vertcat(*(ca.vec(f) for f in frames))
    H = ca.hessian(ca.dot(weights, step(*frames, scene)), stacked)[0]
    rows, cols = H.sparsity().get_triplet()
    return ca.Function("curvature", [*frames, scene, weights], [H]), (rows, cols)


class EffortCurvature:
    """The second-order part of the effort (module docstring) on a transcription ``tr``
    with the strain penalty ``strain`` (a :class:`~.strain.StrainPenalty`)."""

    def __init__(self, tr, strain):
        self.tr, self.strain = tr, strain
        n, N = tr.n, tr.N
        fn, (rows, cols) = weighted_step_hessian(tr)
        self._hessian = Buffered(fn.map(N))
        column = np.full(3 * n, -1)
        column[tr.free_flat] = np.arange(tr.nf)
        steps = np.arange(N)[:, None]
        self._rows, self._cols = (self._global(np.asarray(ix), steps, column, n)
                                  for ix in (rows, cols))
        self._keep = (self._rows >= 0) & (self._cols >= 0)
        self._controlled = tr.problem.controls.idx

    def _global(self, local, steps, column, n):
        """The unknowns' index of each (step, local index in frames n-1, n, n+1); -1 for
        the start, frame -1 or a prescribed component."""
        frame = steps - 1 + local[None, :] // (3 * n)  # step s's frames: s-1, s, s+1
        col = column[local % (3 * n)][None, :]
        return np.where((frame >= 1) & (col >= 0), (frame - 1) * self.tr.nf + col, -1).ravel()

    def __call__(self, z, grad_u) -> sp.csr_matrix:
        """The second-order part at ``z``, ``grad_u`` the control cost's gradient there."""
        tr = self.tr
        w = np.zeros((tr.N, tr.n, 3))
        w[:, self._controlled] = np.reshape(grad_u, (tr.N, self._controlled.size, 3))
        x = tr.frames(z)
        (values,) = self._hessian(*tr._stacked(x), tr.scene_columns(), w)
        k = self._keep
        forces = sp.csr_matrix((values[k], (self._rows[k], self._cols[k])),
                               shape=(tr.size, tr.size))
        return forces + self._strain(z)

    def _strain(self, z) -> sp.csr_matrix:
        """``sum_k r_k d^2 r_k / dz^2`` of the strain penalty's residuals."""
        tr, s = self.tr, self.strain
        rows, cols, vals = [], [], []
        x = tr.frames(z)
        for term in s.terms:
            frames = np.array([n for n in range(1, tr.N + 1) if term.counts(n, tr.dt)], int)
            d, length, excess = term._excess(x[frames])
            frame, spring = np.nonzero(excess > 0)
            if frame.size == 0:
                continue
            scale = term.weight * tr.dt * excess[frame, spring]  # r_k sqrt(weight dt)
            L = length[frame, spring]
            unit = d[frame, spring] / L[:, None]
            block = (scale / (term._rest[spring] * L))[:, None, None] * (
                np.eye(3)[None] - unit[:, :, None] * unit[:, None, :])  # (k, 3, 3)
            base = ((frames[frame] - 1) * tr.nf)[:, None]
            ends = {e: s.column[3 * idx[spring][:, None] + np.arange(3)]
                    for e, idx in (("i", term._i), ("j", term._j))}
            for a, b, sign in (("i", "i", 1), ("j", "j", 1), ("i", "j", -1), ("j", "i", -1)):
                r = np.broadcast_to((base + ends[a])[:, :, None], block.shape)
                c = np.broadcast_to((base + ends[b])[:, None, :], block.shape)
                ok = ((ends[a] >= 0)[:, :, None] & (ends[b] >= 0)[:, None, :])
                rows.append(r[ok]), cols.append(c[ok]), vals.append(sign * block[ok])
        if not rows:
            return sp.csr_matrix((tr.size, tr.size))
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))),
                             shape=(tr.size, tr.size))
