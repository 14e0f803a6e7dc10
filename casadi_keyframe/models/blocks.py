"""Block-sparse Jacobians of interaction laws: 3x3 blocks per pair, per particle and per
stencil of k particles, their products with vectors, and the fixed sparsity pattern they are
gathered into.

A pair law acting on ``d = x_j - x_i`` with force ``+F`` on i and ``-F`` on j has the Jacobian
block ``B = dF/dd`` at (i,j) and (j,i) and ``-B`` at (i,i) and (j,j); a particle's own forces
(drag, colliders) give a diagonal block; a law on a stencil of k particles (a hinge's four)
gives its whole ``3k x 3k`` Jacobian, row-major, its block (a, b) at the particles
``(stencil[a], stencil[b])``.  :class:`Blocks` holds one Jacobian that way;
:class:`BlockPattern` is the structure of such a matrix for fixed pairs and stencils, with
the gather that turns blocks into CSC values in one sparse product, optionally restricted to
the free (unconstrained) components, so a matrix assembled every step keeps one pattern and a
sparse factorisation can analyse it once.  Pairs stay a compact special case (9 numbers for
four blocks).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..kernels import scatter_pairs, scatter_stencils, stencil_values


@dataclass(frozen=True)
class Blocks:
    """One ``3n x 3n`` Jacobian as row-major 3x3 blocks: ``pairs (P, 9)`` for the pairs
    ``(i, j)`` and ``particles (n, 9)`` on the diagonal."""

    i: np.ndarray
    j: np.ndarray
    pairs: np.ndarray
    particles: np.ndarray
    stencils: tuple = ()  # (stencils (P, k), blocks (P, 9 k^2)) per law on k particles

    @property
    def n(self) -> int:
        return self.particles.shape[0]

    def matvec(self, y: np.ndarray, transpose: bool = False) -> np.ndarray:
        """``J y`` (``J^T y`` with ``transpose``) for ``y`` of shape ``(n, 3)`` or flat."""
        y = np.asarray(y).reshape(self.n, 3)
        spec = "pba,pb->pa" if transpose else "pab,pb->pa"
        pairs = np.einsum(spec, self.pairs.reshape(-1, 3, 3), y[self.j] - y[self.i])
        out = np.einsum(spec.replace("p", "k"), self.particles.reshape(-1, 3, 3), y)
        out = out + scatter_pairs(pairs, self.i, self.j, self.n)
        for stencils, blocks in self.stencils:
            m = 3 * stencils.shape[1]
            local = np.einsum(spec, blocks.reshape(-1, m, m), stencil_values(y, stencils))
            out += scatter_stencils(local, stencils, self.n)
        return out

    def scaled_sum(self, others, weights, diagonal=None) -> "Blocks":
        """``w0 self + w1 others[0] + ...`` plus ``diagonal`` (``(n,)``, times the identity
        in each particle block); every term over the same pairs and stencils."""
        pairs, particles = weights[0] * self.pairs, weights[0] * self.particles
        stencils = [weights[0] * b for _, b in self.stencils]
        for blocks, w in zip(others, weights[1:]):
            pairs, particles = pairs + w * blocks.pairs, particles + w * blocks.particles
            stencils = [s + w * b for s, (_, b) in zip(stencils, blocks.stencils)]
        if diagonal is not None:
            particles = particles + np.outer(diagonal, np.eye(3).ravel())
        return Blocks(self.i, self.j, pairs, particles,
                      tuple((idx, b) for (idx, _), b in zip(self.stencils, stencils)))

    @property
    def stencil_blocks(self) -> tuple:
        """The stencils' blocks alone, in :meth:`BlockPattern.values`' order."""
        return tuple(b for _, b in self.stencils)


@dataclass(frozen=True)
class SparseJacobian:
    """A Jacobian given as a sparse matrix, with :meth:`Blocks.matvec`'s interface (for
    models that give ``jacobians`` but no blocks)."""

    matrix: object

    def matvec(self, y: np.ndarray, transpose: bool = False) -> np.ndarray:
        y = np.asarray(y)
        return ((self.matrix.T if transpose else self.matrix) @ y.ravel()).reshape(y.shape)


class BlockPattern:
    """The CSC structure of a matrix of :class:`Blocks` over fixed pairs ``(i, j)`` and
    ``stencils`` (a tuple of ``(P, k)`` index arrays) of n particles, restricted to the
    components where ``free`` (flat, ``3n``) is True (all by default; the rows and columns
    of the others are dropped) and, unless ``particle_blocks`` is False, with every
    particle's diagonal block.  ``values(pairs, particles, stencils)`` gives the CSC data in
    that structure by one product with ``gather``, so every matrix with these pairs and
    stencils shares ``indices`` and ``indptr``."""

    def __init__(self, i: np.ndarray, j: np.ndarray, n: int, free: np.ndarray | None = None,
                 particle_blocks: bool = True, stencils: tuple = ()):
        self.i, self.j, self.n = np.asarray(i, np.intp), np.asarray(j, np.intp), n
        self.stencils = tuple(np.asarray(s, np.intp) for s in stencils)
        k = np.arange(n if particle_blocks else 0)
        bi = np.concatenate([self.i, self.i, self.j, self.j, k])
        bj = np.concatenate([self.i, self.j, self.i, self.j, k])
        a, b = np.divmod(np.arange(9), 3)  # row-major entry e of a block is (a, b)
        rows, cols = (3 * bi[:, None] + a).ravel(), (3 * bj[:, None] + b).ravel()
        P = self.i.size
        source = np.concatenate([np.tile(np.arange(9 * P), 4), 9 * P + np.arange(9 * k.size)])
        sign = np.concatenate([-np.ones(9 * P), np.ones(18 * P), -np.ones(9 * P),
                               np.ones(9 * k.size)])
        width = 9 * (P + k.size)
        for stencil in self.stencils:
            r, c, size = _stencil_entries(stencil)
            rows, cols = np.concatenate([rows, r]), np.concatenate([cols, c])
            source = np.concatenate([source, width + np.arange(size)])
            sign = np.concatenate([sign, np.ones(size)])
            width += size
        free = np.ones(3 * n, bool) if free is None else np.asarray(free, bool)
        keep = free[rows] & free[cols]
        number = np.cumsum(free) - 1  # a free component's index among the free ones
        rows, cols, source, sign = number[rows[keep]], number[cols[keep]], source[keep], sign[keep]
        self.size = int(free.sum())
        keys, slot = np.unique(cols.astype(np.int64) * self.size + rows, return_inverse=True)
        self.indices = (keys % self.size).astype(np.int32)
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(keys // self.size,
                                                                 minlength=self.size))])
        self.indptr = self.indptr.astype(np.int32)
        self.gather = sp.csr_matrix((sign, (slot.ravel(), source)), shape=(keys.size, width))
        self.free = free
        self.has_particle_blocks = particle_blocks

    @property
    def nnz(self) -> int:
        return self.indices.size

    @functools.cached_property
    def block_slots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every 3x3 block of the pattern between two free particles: the particles ``(I,
        J)`` and the positions ``(B, 9)`` of its entries (row-major) in the CSC data."""
        k = np.arange(self.n) if self.has_particle_blocks else np.zeros(0, np.intp)
        linked = [self.i * self.n + self.j, self.j * self.n + self.i, k * self.n + k]
        for stencil in self.stencils:
            linked += [stencil[:, a] * self.n + stencil[:, b]
                       for a in range(stencil.shape[1]) for b in range(stencil.shape[1])]
        keys = np.unique(np.concatenate(linked))
        I, J = np.divmod(keys, self.n)
        whole = self.free.reshape(self.n, 3).all(axis=1)
        I, J = I[whole[I] & whole[J]], J[whole[I] & whole[J]]
        number = np.cumsum(self.free) - 1
        a, b = np.divmod(np.arange(9), 3)
        rows, cols = number[3 * I[:, None] + a], number[3 * J[:, None] + b]
        col_of = np.repeat(np.arange(self.size), np.diff(self.indptr))
        stored = col_of.astype(np.int64) * self.size + self.indices
        slots = np.searchsorted(stored, cols.astype(np.int64) * self.size + rows)
        return I, J, slots

    def projected(self, values: np.ndarray, projector: np.ndarray, touched: np.ndarray,
                  masses: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """The CSC data of ``S A S + M P`` for the matrix A of ``values``, with ``P`` the
        ``(n, 3, 3)`` blocks of ``projector`` (nonzero on the ``touched`` particles only),
        ``S = I - P`` and M the diagonal of ``masses``: a constrained step's matrix, with the
        pattern and the positive definiteness of A; ``extra`` ``(n, 3, 3)``: blocks added to
        the touched particles' diagonal after the projection (sliding friction's)."""
        I, J, slots = self.block_slots
        pick = touched[I] | touched[J]
        if not pick.any():
            return values
        I, J, slots = I[pick], J[pick], slots[pick]
        B = values[slots].reshape(-1, 3, 3)
        PI, PJ = projector[I], projector[J]
        B = B - PI @ B - B @ PJ + PI @ B @ PJ
        diagonal = I == J
        B[diagonal] += masses[I[diagonal], None, None] * PI[diagonal]
        if extra is not None:
            B[diagonal] += extra[I[diagonal]]
        out = values.copy()
        out[slots] = B.reshape(-1, 9)
        return out

    def values(self, pairs: np.ndarray, particles: np.ndarray | None = None,
               stencils: tuple = ()) -> np.ndarray:
        """CSC data of the matrix with ``(P, 9)`` pair blocks, ``(n, 9)`` particle blocks
        (none for a pattern built without ``particle_blocks``) and each stencil law's
        ``(P_s, 9 k^2)`` blocks, in the order of the pattern's ``stencils``."""
        parts = [pairs.ravel()] + ([] if particles is None else [particles.ravel()])
        parts += [b.ravel() for b in stencils]
        return self.gather @ (parts[0] if len(parts) == 1 else np.concatenate(parts))

    def matrix(self, pairs: np.ndarray, particles: np.ndarray | None = None,
               stencils: tuple = ()) -> sp.csc_matrix:
        """The matrix itself (the free block when the pattern is restricted)."""
        return sp.csc_matrix((self.values(pairs, particles, stencils), self.indices.copy(),
                              self.indptr.copy()), shape=(self.size, self.size))


def _stencil_entries(stencils: np.ndarray):
    """``(rows, cols, count)`` of every entry of the row-major ``3k x 3k`` blocks of
    ``(P, k)`` stencils, stencil after stencil, in the ``3n x 3n`` matrix."""
    P, k = stencils.shape
    m = 3 * k
    r, c = np.divmod(np.arange(m * m), m)
    rows = (3 * stencils[:, r // 3] + r % 3).ravel()
    cols = (3 * stencils[:, c // 3] + c % 3).ravel()
    return rows, cols, P * m * m


def pair_block_matrices(i: np.ndarray, j: np.ndarray, n: int, *blocks: np.ndarray) -> list:
    """One ``3n x 3n`` CSC matrix per ``(P, 9)`` row-major block array ``B``: ``-B`` at (i,i),
    (j,j) and ``+B`` at (i,j), (j,i), for pairs that change every step (self-contacts); the
    pattern is built once for all of them."""
    pattern = BlockPattern(i, j, n, particle_blocks=False)
    return [pattern.matrix(b) for b in blocks]


class GrowingPattern:
    """The pattern of one pass's step matrices: a fixed pattern (the fixed pairs' and
    stencils', restricted to the free components) plus every extra pair (self-contact) met
    so far.  It grows when a
    matrix has a pair it lacks and never shrinks within the pass, so a factorisation
    re-analyses only when contact spreads; each growth makes a new :class:`BlockPattern`
    (its identity is the structure key)."""

    def __init__(self, fixed: BlockPattern):
        self.fixed = self.pattern = fixed
        self.extra = np.zeros(0, np.int64)  # sorted keys i * n + j of the extra pairs
        self.growths = 0

    def values(self, blocks: Blocks) -> np.ndarray:
        """CSC data of ``blocks`` (the fixed pairs first, then extra pairs) in
        :attr:`pattern`, grown first if ``blocks`` has pairs it lacks."""
        fixed, n = self.fixed, self.fixed.n
        S = fixed.i.size
        keys = blocks.i[S:].astype(np.int64) * n + blocks.j[S:]
        if keys.size and not np.all(np.isin(keys, self.extra, assume_unique=True)):
            self.extra = np.union1d(self.extra, keys)
            i, j = np.divmod(self.extra, n)
            self.pattern = BlockPattern(np.concatenate([fixed.i, i]),
                                        np.concatenate([fixed.j, j]), n, fixed.free,
                                        stencils=fixed.stencils)
            self.growths += 1
        pairs = np.zeros((S + self.extra.size, 9))
        pairs[:S] = blocks.pairs[:S]
        pairs[S + np.searchsorted(self.extra, keys)] = blocks.pairs[S:]
        return self.pattern.values(pairs, blocks.particles, blocks.stencil_blocks)
