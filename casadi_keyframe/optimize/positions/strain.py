"""The problem's own strain limit in positions: each :class:`~...objectives.StrainLimit`
term, ``0.5 weight dt sum max(0, s - limit)^2`` over the springs' stretches ``s`` at its
frames, is a sum of squared residuals of the positions, added to the effort the search
minimises with its Gauss-Newton matrix (the keyframes are constraints, the control cost and
this penalty the objective: the problem's statement less its keyframe terms).  Without it,
least effort lets a sheet hang from its pins as far as gravity stretches it."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...objectives import StrainLimit


class StrainPenalty:
    """The problem's :class:`StrainLimit` terms on a transcription ``tr`` (none: zero)."""

    def __init__(self, tr):
        self.tr = tr
        self.terms = [t for t in tr.problem.objective_terms.trajectory_terms
                      if isinstance(t, StrainLimit) and t.weight > 0]
        column = np.full(3 * tr.n, -1)
        column[tr.free_flat] = np.arange(tr.nf)
        self.column = column  # a component's column within a frame's unknowns (-1: fixed)

    def residuals(self, z, jacobian: bool = True):
        """``(r, Jr)``: the residuals (``0.5 |r|^2`` is the penalty) and, when asked, their
        sparse Jacobian in ``z``."""
        tr = self.tr
        x = tr.frames(z)
        rs, rows, cols, vals, start = [], [], [], [], 0
        for term in self.terms:
            frames = np.array([n for n in range(1, tr.N + 1) if term.counts(n, tr.dt)], int)
            d, length, excess = term._excess(x[frames])
            frame, spring = np.nonzero(excess > 0)
            scale = np.sqrt(term.weight * tr.dt)
            rs.append(scale * excess[frame, spring])
            if jacobian and frame.size:
                unit = d[frame, spring] / (length[frame, spring] * term._rest[spring])[:, None]
                for end, sign in ((term._j, 1.0), (term._i, -1.0)):
                    comp = 3 * end[spring][:, None] + np.arange(3)  # (k, 3)
                    col = self.column[comp]
                    keep = col >= 0
                    base = (frames[frame] - 1)[:, None] * tr.nf
                    rows.append(np.broadcast_to(start + np.arange(frame.size)[:, None],
                                                comp.shape)[keep])
                    cols.append((base + col)[keep])
                    vals.append((sign * scale * unit)[keep])
            start += frame.size
        r = np.concatenate(rs) if rs else np.zeros(0)
        if not jacobian:
            return r, None
        if not rows:
            return r, sp.csr_matrix((r.size, tr.size))
        J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(r.size, tr.size))
        return r, J

    def pattern(self) -> sp.csr_matrix:
        """Where the residuals' Jacobian can hold a value: a row of ones per spring and
        counted frame, whatever its stretch."""
        tr, rows, cols, start = self.tr, [], [], 0
        for term in self.terms:
            frames = np.array([n for n in range(1, tr.N + 1) if term.counts(n, tr.dt)], int)
            frame, spring = (a.ravel() for a in np.meshgrid(np.arange(frames.size),
                                                              np.arange(term._rest.size),
                                                              indexing="ij"))
            for end in (term._j, term._i):
                comp = 3 * end[spring][:, None] + np.arange(3)
                col = self.column[comp]
                keep = col >= 0
                base = (frames[frame] - 1)[:, None] * tr.nf
                rows.append(np.broadcast_to(start + np.arange(frame.size)[:, None],
                                            comp.shape)[keep])
                cols.append((base + col)[keep])
            start += frame.size
        if not rows:
            return sp.csr_matrix((0, tr.size))
        r, c = np.concatenate(rows), np.concatenate(cols)
        return sp.csr_matrix((np.ones(r.size), (r, c)), shape=(start, tr.size))
