r"""A second-order correction of a step in positions for the cloth's stiff springs.

The effort's Gauss-Newton model takes each force to first order in the positions.  A step
that turns part of a cloth moves its particles along tangents, and a stiff spring turned by
an angle theta gets longer by about ``L theta^2 / 2``: its force grows with ``k_t`` at fourth
order in the step, which no quadratic model sees, so a search on the model alone must take
tiny steps wherever the cloth turns.  The correction moves every frame's particles the
least (mass-weighted) distance that brings each stiff spring the step stretched beyond the
length the model expected back to that length (Goldenthal et al. 2007, "Efficient
simulation of inextensible cloth": fast projection), by a few Gauss-Newton iterations on
the springs' lengths, each kept only if it lowers the springs' squared excess (where more
springs meet at a particle than it has freedoms, their lengths can conflict): a curvilinear
step the merit then judges as any other.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ...models.springs import BEND, ChoiKoSprings

ITERATIONS = 4
SLACK = 1e-6  # relative: a spring this close to its expected length is left alone
DAMPING = 1e-3  # of the projection's normal matrix's diagonal, added to it


def _excess(length, target) -> float:
    """The squared excess of the springs over their targets (the projection's measure)."""
    return float(np.sum(np.maximum(length - target, 0.0) ** 2))


class LengthRestoration:
    """The module docstring's correction for a transcription ``tr`` (no stiff springs: none)."""

    def __init__(self, tr):
        self.tr = tr
        family = next((f for f in getattr(tr.problem.model, "families", ())
                       if isinstance(f, ChoiKoSprings)), None)
        self.active = family is not None
        if not self.active:
            return
        s = family.springs
        stiff = s.kind != BEND
        self.i, self.j, self.rest = s.i[stiff], s.j[stiff], s.rest[stiff]
        weight = np.where(tr.free, 1.0 / tr.problem.model.masses[:, None], 0.0)
        self.weight = weight  # (n, 3): inverse mass on free components, 0 on constrained

    def lengths(self, x):
        d = x[:, self.j] - x[:, self.i]
        return np.sqrt(np.einsum("...a,...a->...", d, d)), d

    def __call__(self, z_from, z_to):
        """``z_to`` (a step from ``z_from``) with its stiff springs restored (see module)."""
        if not self.active:
            return z_to
        tr = self.tr
        x0, x = tr.frames(z_from)[1:], tr.frames(z_to)[1:]
        length0, d0 = self.lengths(x0)
        dx = x - x0
        expected = length0 + np.einsum("...a,...a->...", d0 / length0[..., None],
                                       dx[:, self.j] - dx[:, self.i])
        target = np.maximum(expected, self.rest)
        length, d = self.lengths(x)
        worst = _excess(length, target)
        for _ in range(ITERATIONS):
            excess = length - target
            frame, spring = np.nonzero(excess > SLACK * self.rest)
            if frame.size == 0:
                break
            moved = x + self._projection(x, d, length, excess, frame, spring)
            length_m, d_m = self.lengths(moved)
            if _excess(length_m, target) >= worst:  # the springs' targets conflict: stop
                break
            x, length, d, worst = moved, length_m, d_m, _excess(length_m, target)
        return tr.unknowns(np.concatenate([tr.base[:1], x]))

    def _projection(self, x, d, length, excess, frame, spring):
        """The least weighted move that removes ``excess`` of the springs ``(frame,
        spring)`` to first order: ``-W G^T (G W G^T)^-1 excess``."""
        n = self.tr.n
        u = d[frame, spring] / length[frame, spring][:, None]  # (k, 3)
        ends = np.stack([frame * n + self.i[spring], frame * n + self.j[spring]], axis=1)
        signs = np.array([-1.0, 1.0])
        rows = np.repeat(np.arange(frame.size), 6)
        cols = (3 * ends[:, :, None] + np.arange(3)).reshape(-1)
        vals = (signs[None, :, None] * u[:, None, :]).reshape(-1)
        shape = (frame.size, x.size)
        G = sp.csr_matrix((vals, (rows, cols)), shape=shape)
        W = sp.diags(np.tile(self.weight.ravel(), x.shape[0]))
        GW = G @ W
        S = (GW @ G.T).tocsc()
        # damped: more springs than a particle has freedoms ask for lengths that conflict
        S = S + sp.diags(DAMPING * S.diagonal() + 1e-12 * np.max(self.weight))
        lam = splu(S).solve(excess[frame, spring])
        return -(GW.T @ lam).reshape(x.shape)
