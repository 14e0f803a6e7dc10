"""Sparse Cholesky for symmetric positive definite systems: CHOLMOD's supernodal
factorisation (Chen, Davis, Hager and Rajamanickam, 2008), through the cvxopt package, whose
wheels bundle CHOLMOD with OpenBLAS.

The analysis (fill-reducing ordering, elimination tree, supernodes) depends only on the
sparsity pattern.  A CHOLMOD factor object holds one analysis and one numeric factorisation,
so the plan keeps, per :attr:`System.structure`, a factor object shared by the factorisations
nobody keeps (each refactorises it numerically; using an older one after a newer one raises)
and a pool of factor objects for the factorisations that must outlive the next one
(``factor(A, keep=True)``, kept for the adjoint pass).  A kept factor goes back to the pool
when its owner releases it (:meth:`CholeskyFactor.release`, after the backward pass), so the
next pass over the same pattern refactorises numerically only.  The solver object holds
settings only; the plan holds this state and lives as long as its owner keeps it.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np

from .system import Factored, Plan, SolveError, SolveInfo

try:
    from cvxopt import cholmod as _cholmod, matrix as _dense, spmatrix as _sparse
except ImportError:  # optional: linear_solver("auto") falls back to SuperLU
    _cholmod = None

KEPT_PATTERNS = 4  # the analyses a plan keeps: the fixed pattern and the latest grown ones


def available() -> bool:
    """Whether CHOLMOD (the cvxopt package) can be imported."""
    return _cholmod is not None


class SparseCholesky:
    """CHOLMOD's supernodal Cholesky of the free block (module docstring); refuses a matrix
    that is not positive definite.  Settings only: :meth:`init` makes the state."""

    name = "cholmod"

    def __init__(self):
        if _cholmod is None:
            raise ImportError("solver 'cholmod' needs the cvxopt package (it bundles CHOLMOD): "
                              "pip install cvxopt, or use solver='direct' (SuperLU)")

    def init(self, free: np.ndarray) -> "CholeskyPlan":
        return CholeskyPlan(np.asarray(free, bool))


class Analysis:
    """One pattern's analyses: where A_ff's lower triangle sits in its CSC data, a CHOLMOD
    matrix of that pattern to load values into, the shared factor object and the pool of
    factor objects free for kept factorisations."""

    def __init__(self, block, plan):
        col = np.repeat(np.arange(block.shape[1]), np.diff(block.indptr))
        lower = np.flatnonzero(block.indices >= col)
        rows, cols = block.indices[lower], col[lower]
        probe = _sparse(np.arange(lower.size, dtype=float), rows.tolist(), cols.tolist(),
                        block.shape)
        self.lower = lower[np.asarray(probe.V, dtype=np.intp).ravel()]  # CHOLMOD's order
        self.matrix = probe
        self.plan = plan
        self.shared = None
        self.generation = 0
        self.pool = []
        self.factor_nbytes = None

    def load(self, block) -> None:
        self.matrix.V = _dense(block.data[self.lower])

    def symbolic(self):
        """A new factor object of this pattern (one CHOLMOD analysis, counted)."""
        self.plan.analyses += 1
        return _cholmod.symbolic(self.matrix)

    def measure(self) -> None:
        """Set :attr:`factor_nbytes` (12 bytes per entry of L) from a throwaway factor of the
        loaded matrix: reading a factor's entries spoils it for solves."""
        factor = self.symbolic()
        _cholmod.numeric(self.matrix, factor)
        self.factor_nbytes = 12 * len(_cholmod.getfactor(factor).V)


class CholeskyPlan(Plan):
    """A pass's or a series of passes' CHOLMOD state: the analyses of the patterns met (at
    most :data:`KEPT_PATTERNS`, most recent first kept) and ``analyses``, how many CHOLMOD
    analyses it has made."""

    def __init__(self, free: np.ndarray):
        super().__init__(free)
        self.patterns: OrderedDict = OrderedDict()
        self.analyses = 0

    def _analysis(self, system) -> Analysis:
        structure = system.structure
        if structure is None:
            return Analysis(system.free_block, self)
        analysis = self.patterns.get(structure)
        if analysis is None:
            analysis = self.patterns[structure] = Analysis(system.free_block, self)
            while len(self.patterns) > KEPT_PATTERNS:
                self.patterns.popitem(last=False)
        else:
            self.patterns.move_to_end(structure)
        return analysis

    def factor(self, A, keep: bool = False) -> "CholeskyFactor":
        """The Cholesky factor of A's free block; one that is not positive definite raises
        SolveError.  ``keep``: the factor stays valid after later ones until released."""
        system = self.system(A)
        analysis = self._analysis(system)
        analysis.load(system.free_block)
        generation = None
        if keep:
            symbolic = analysis.pool.pop() if analysis.pool else analysis.symbolic()
        else:
            if analysis.shared is None:
                analysis.shared = analysis.symbolic()
            symbolic = analysis.shared
            analysis.generation += 1  # every earlier factor sharing it is now stale
            generation = analysis.generation
        try:
            _cholmod.numeric(analysis.matrix, symbolic)
        except ArithmeticError:
            if keep:
                analysis.pool.append(symbolic)
            raise SolveError("the step matrix is not positive definite (Cholesky failed): "
                             "stiff compression or contact at this dt; reduce dt") from None
        if keep and analysis.factor_nbytes is None:
            analysis.measure()
        return CholeskyFactor(system, self, symbolic, analysis, generation)


class CholeskyFactor(Factored):
    def __init__(self, system, plan, factor, analysis, generation):
        super().__init__(system, plan)
        self.factor, self.analysis, self.generation = factor, analysis, generation

    @property
    def kept(self) -> bool:
        return self.generation is None

    def release(self) -> None:
        """Hand a kept factor's analysis back to its plan's pool (it cannot solve after)."""
        if self.kept and self.factor is not None:
            self.analysis.pool.append(self.factor)
            self.factor = None

    @property
    def usable(self) -> bool:
        if self.kept:
            return self.factor is not None
        return self.generation == self.analysis.generation

    @property
    def nbytes(self) -> int:
        """An estimate: 12 bytes per entry of L (known after the pattern's first kept
        factor; 0 before)."""
        return self.analysis.factor_nbytes or 0

    def _solve_free(self, rhs, transpose: bool, x0, tol):
        if self.kept and self.factor is None:
            raise RuntimeError("this Cholesky factor was released to its plan; solve before "
                               "releasing, or factor again")
        if not self.usable:
            raise RuntimeError("this Cholesky factor was overwritten by a later factorisation "
                               "of the same plan; factor(A, keep=True) keeps one")
        x = _dense(rhs)
        _cholmod.solve(self.factor, x)
        x = np.asarray(x).ravel()
        return x, SolveInfo(0, None)  # Cholesky is backward stable: no residual check
