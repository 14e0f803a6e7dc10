"""Multiple shooting as a constrained problem for IPOPT (:func:`~.ipopt.search`): the
objective on the stitched segments, the scaled defects as equality constraints.

IPOPT needs the constraints' Jacobian as a matrix: each defect row is one backward sweep
over its segment (:meth:`~.form.Shooting.defect_jacobian`, reusing the forward pass's
factorisations, in the workers that ran it), so a Jacobian costs ``2 x free components``
sweeps per segment, and the Lagrangian's Hessian is IPOPT's limited-memory one.  The
objective, its gradient and the defects come from the evaluator's one memoised evaluation
per point.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..methods.ipopt import search


class Defects:
    """The scaled defects as IPOPT's equality constraints: their values at z from the
    evaluator ``ev`` (memoised there), their Jacobian at z (kept for the last z) and its
    ``pattern``, read from the Jacobian at ``z0``."""

    def __init__(self, ev, shooting, runner, z0):
        self.ev, self.shooting, self.runner = ev, shooting, runner
        self.size = 2 * shooting.nf * (shooting.K - 1)
        self.jz, self.jac = None, None
        self.pattern = jacobian_pattern(shooting, self.jacobian(z0))

    def values(self, z) -> np.ndarray:
        self.ev(z)
        info = self.ev.last_info
        return (self.shooting.defect_vector(info.defects) if info is not None
                else np.full(self.size, 1e10))

    def jacobian(self, z):
        z = np.asarray(z, dtype=float).ravel()
        if self.jz is None or not np.array_equal(z, self.jz):
            self.ev(z)  # the segments' records are the last evaluation's: z's
            self.jac = self.shooting.defect_jacobian(self.runner).tocsc()
            self.jz = z
        return self.jac


def jacobian_pattern(shooting, jac) -> ca.Sparsity:
    """The defects' Jacobian pattern: where a structurally nonzero block may be (each
    segment's forces and start, the next node), read from one Jacobian's block layout."""
    dense_rows = []
    for k in range(shooting.K - 1):
        rows = slice(2 * shooting.nf * k, 2 * shooting.nf * (k + 1))
        block = jac[rows]
        cols = np.flatnonzero(np.asarray(abs(block).sum(axis=0)).ravel() > 0)
        dense_rows.append((rows, cols))
    r, c = [], []
    for rows, cols in dense_rows:
        for i in range(rows.start, rows.stop):
            r.extend([i] * cols.size)
            c.extend(cols.tolist())
    return ca.Sparsity.triplet(jac.shape[0], jac.shape[1], r, c)


def run_nlp(shooting, runner, ev, z0, maxiter, tol, options, on_iteration, deadline):
    """IPOPT on the constrained form from ``z0``; ``on_iteration(z)`` after each
    iteration.  Returns ``(status, message, z)`` with IPOPT's last point; an interrupt
    raises, the goal met raises :class:`~.goal.GoalReached`."""
    return search(ev, z0, shooting.bounds(), maxiter, tol, options, on_iteration, deadline,
                  constraints=Defects(ev, shooting, runner, z0), name="shooting")
