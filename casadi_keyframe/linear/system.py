"""What every linear solver shares: the system it is given, the plan it keeps, how a solve
went and how it fails.

Every solve is of the reduced system: constrained (pinned, attached) components take their
prescribed value ``z`` and the free ones solve ``A_ff x_f = b_f - A_fc z_c``.  A solver sees a
matrix as a :class:`System`: its free block and its products with the whole matrix.  A
:class:`System` built from a fixed sparsity pattern (the cloth step's, gathered from its
blocks) carries that pattern's ``structure`` key, so a sparse factorisation analyses the
pattern once; any scipy matrix is accepted too (:meth:`System.from_matrix`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp


class SolveError(RuntimeError):
    """The linear solve failed: not converged, not positive definite, or singular."""


@dataclass(frozen=True)
class SolveInfo:
    """How a solve went: ``iterations`` (0 for a direct solve) and the final relative
    ``residual`` of the free block (CG: in its preconditioner's norm; None where it is not
    computed: a Cholesky solve is backward stable, and an indefinite matrix fails to factor)."""

    iterations: int
    residual: float | None


@dataclass(frozen=True)
class System:
    """A square matrix A as the solvers see it.

    ``free_block``: ``A_ff`` as CSC (both triangles).  ``matvec(y)`` / ``rmatvec(y)``: ``A y``
    and ``A^T y`` for whole vectors (the constrained part of a solve).  ``structure``: an
    object shared by every System whose free block has the same sparsity pattern (a
    factorisation may reuse its analysis), None when unknown.  ``symmetric``: A = A^T."""

    free_block: sp.csc_matrix
    matvec: Callable[[np.ndarray], np.ndarray]
    rmatvec: Callable[[np.ndarray], np.ndarray]
    structure: object = None
    symmetric: bool = True

    @classmethod
    def from_matrix(cls, A, free: np.ndarray, symmetric: bool = True) -> "System":
        """The System of a whole sparse (or dense) matrix ``A`` with free components
        ``free``; its pattern is analysed afresh by every factorisation."""
        A = sp.csr_matrix(A)
        index = np.flatnonzero(free)
        block = A[index][:, index].tocsc()
        block.sort_indices()
        return cls(block, A.dot, A.T.tocsr().dot, None, symmetric)


class Plan:
    """What a solver keeps for the matrices of one or more passes: the free components (and,
    for a factorisation, its analyses).  ``worth_keeping``: whether a prepared matrix saves
    enough work when reused (a derivative pass) to be kept in memory."""

    worth_keeping = True

    def __init__(self, free: np.ndarray):
        self.free = np.asarray(free, bool)

    def system(self, A, symmetric: bool = True) -> System:
        """``A`` itself if a :class:`System`, else :meth:`System.from_matrix`."""
        return A if isinstance(A, System) else System.from_matrix(A, self.free, symmetric)


class Factored:
    """Base of a prepared matrix: solves on the free block with the constrained part moved
    to the right-hand side.  Subclasses give ``_solve_free(rhs, transpose, x0, tol)``
    returning ``(x_f, SolveInfo)``."""

    def __init__(self, system: System, plan: Plan):
        self.system, self.plan = system, plan

    #: bytes this prepared matrix holds beyond the System (what keeping it costs)
    nbytes = 0

    @property
    def usable(self) -> bool:
        """Whether it can still solve (not released, not overwritten)."""
        return True

    def release(self) -> None:
        """Give what a kept factorisation holds back to its plan (nothing here)."""

    def solve(self, b, z=None, *, x0=None, tol: float | None = None):
        """``(x, SolveInfo)`` of ``A x = b`` with ``x = z`` on the constrained components
        (zero without z); ``x0`` warm-starts an iterative solver's free components and
        ``tol`` overrides its tolerance (direct solvers ignore both)."""
        return self._solve(b, z, False, x0, tol)

    def solve_transpose(self, b, z=None, *, x0=None, tol: float | None = None):
        """``A^T x = b``, the same way and with the same factors."""
        return self._solve(b, z, True, x0, tol)

    def _solve(self, b, z, transpose: bool, x0, tol):
        free = self.plan.free
        x = np.zeros_like(b) if z is None else np.where(free, 0.0, z)
        rhs = b[free]
        if z is not None and np.any(x):  # a prescribed motion to move to the right
            product = self.system.rmatvec if transpose else self.system.matvec
            rhs = rhs - product(x)[free]
        start = None if x0 is None else np.asarray(x0)[free]
        x[free], info = self._solve_free(rhs, transpose, start, tol)
        return x, info

    def _solve_free(self, rhs, transpose: bool, x0, tol):
        raise NotImplementedError

    def residual(self, x_f, rhs, transpose: bool) -> float:
        """``|A_ff x_f - rhs| / |rhs|`` (0 for a zero right-hand side)."""
        block = self.system.free_block.T if transpose else self.system.free_block
        scale = np.linalg.norm(rhs)
        return float(np.linalg.norm(block @ x_f - rhs) / scale) if scale > 0 else 0.0
