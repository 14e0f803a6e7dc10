r"""A revision that only lets particles go, solved on the factor the step already has.

A step's held solve factorises ``A_hat = S A S + M P`` (:mod:`.held_solve`).  When its end
shows that the hold pulled some members onto their body, the step is solved again without
them; nothing else changes.  Their held directions (a normal, or a sticking particle's
three) are an orthonormal ``Q`` (``3n x m``).  The new matrix is ``S' A S' + M P'``, with
``S' = S + Q Q^T`` and ``P' = P - Q Q^T``: the old one bordered on ``Q``.  Its solution of a
right-hand side ``r`` (in the range of ``S'``) is, with ``Z = A_hat^-1 S A Q`` (m solves with
the old factor) and the Schur complement ``C = Q^T A Q - (A Q)^T Z``:

    w0 = A_hat^-1 (r - Q Q^T r),   C alpha = Q^T r - (A Q)^T w0,   y = w0 - Z alpha + Q alpha

This is exact, not an approximation. It is symmetric, so the backward and tangent passes
solve with it too.  The Schur complement subtracts two terms of the stiff step's size, so
each solve is refined once against the new matrix's own product (the residual solved
again). That brings it to a factorisation's accuracy.  It pays while m + 2 solves cost less
than a numeric refactorisation (:data:`RANK`).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ..linear.system import Factored

RANK = 8  # released directions up to which bordering the factor beats refactorising it


def released_directions(old, new, n: int):
    """``Q`` ``(3n, m)``: the directions ``old`` held and ``new`` (a subset of its members,
    each held as before) lets go; None if ``new`` is not such a subset or a dropped member
    slid (its friction's blocks were in the matrix: more changed than the directions)."""
    if old is None or new is None or not np.isin(new.particles, old.particles).all():
        return None
    at = np.searchsorted(old.particles, new.particles)
    fields = ["body", "normals", "targets"]
    fields += ["normal", "stick", "blocks"] if old.frictional else []
    for name in fields:
        if not np.array_equal(getattr(old, name)[at], getattr(new, name)):
            return None
    dropped = np.ones(old.count, bool)
    dropped[at] = False
    if old.frictional and old.blocks[dropped].any():
        return None
    blocks = old.projector(n)
    columns = []
    for p in old.particles[dropped]:
        values, vectors = np.linalg.eigh(blocks[p])  # P's range: the held directions
        for direction in vectors[:, values > 0.5].T:
            column = np.zeros(3 * n)
            column[3 * p:3 * p + 3] = direction
            columns.append(column)
    return np.array(columns).reshape(-1, 3 * n).T


class ReleasedFactor(Factored):
    """The solves of a step revised by releases only, on ``base`` (the prepared matrix of
    ``A_hat`` for the ``old`` held set) bordered on the released directions ``Q``
    (:func:`released_directions`); ``plain`` is the step matrix A's free block, unprojected,
    ``free`` the free components and ``product`` the new matrix's (the residual's) product
    (module docstring)."""

    def __init__(self, base, old, Q, plain, free, product):
        super().__init__(base.system, base.plan)
        self.base, self.Q, self.product, self.free = base, Q, product, free
        AQ = np.zeros_like(Q)
        AQ[free] = plain @ Q[free]
        self.AQ = AQ
        projected = np.stack([old.unheld_part(c).ravel() for c in AQ.T], axis=1)
        self.Z = np.stack([base.solve(c)[0] for c in projected.T], axis=1)
        C = Q.T @ AQ - AQ.T @ self.Z
        self.schur = sla.cho_factor((C + C.T) / 2)

    @property
    def rank(self) -> int:
        return self.Q.shape[1]

    @property
    def usable(self) -> bool:
        return self.base.usable

    @property
    def nbytes(self) -> int:
        return self.base.nbytes + self.Z.nbytes + self.AQ.nbytes + self.Q.nbytes

    def release(self) -> None:
        self.base.release()

    def _bordered(self, b, x0, tol):
        along = self.Q.T @ b
        w0, info = self.base.solve(b - self.Q @ along, x0=x0, tol=tol)
        alpha = sla.cho_solve(self.schur, along - self.AQ.T @ w0)
        return w0 + (self.Q - self.Z) @ alpha, info

    def _solve(self, b, z, transpose: bool, x0, tol):
        if z is not None and np.any(z):
            raise ValueError("a released step's factor solves the held solve's projected "
                             "system only (no prescribed components)")
        b = np.where(self.free, b, 0.0)
        y, info = self._bordered(b, x0, tol)
        residual = np.where(self.free, b - self.product(y), 0.0)
        return y + self._bordered(residual, None, tol)[0], info
