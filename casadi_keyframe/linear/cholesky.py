"""Sparse Cholesky for symmetric positive definite systems: CHOLMOD's supernodal
factorisation (Chen, Davis, Hager and Rajamanickam, 2008), through the cvxopt package, whose
wheels bundle CHOLMOD with OpenBLAS.

The analysis (fill-reducing ordering, elimination tree, supernodes) depends only on the
sparsity pattern: a plan keeps one per :attr:`System.structure` and refactorises numerically
for every new matrix of that pattern.  A factorisation that must outlive the next one (kept
for the adjoint pass) gets its own analysis (``factor(A, keep=True)``); the others share
the plan's, and using one after a later factorisation has replaced it raises.  A kept
factor nothing refers to any more hands its analysis (and its memory) back to the solver
object, so the next pass over the same pattern refactorises numerically only.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .system import Factored, Plan, SolveError, SolveInfo

try:
    from cvxopt import cholmod as _cholmod, matrix as _dense, spmatrix as _sparse
except ImportError:  # optional: linear_solver("auto") falls back to SuperLU
    _cholmod = None


def available() -> bool:
    """Whether CHOLMOD (the cvxopt package) can be imported."""
    return _cholmod is not None


class SparseCholesky:
    """CHOLMOD's supernodal Cholesky of the free block (module docstring); refuses a matrix
    that is not positive definite."""

    name = "cholmod"

    def __init__(self):
        if _cholmod is None:
            raise ImportError("solver 'cholmod' needs the cvxopt package (it bundles CHOLMOD): "
                              "pip install cvxopt, or use solver='direct' (SuperLU)")
        self._spare = (None, [])  # (structure, analyses of dropped kept factors)

    def _take_spare(self, structure):
        held, spare = self._spare
        return spare.pop() if structure is not None and held is structure and spare else None

    def _give_back(self, structure, symbolic) -> None:
        held, spare = self._spare
        if structure is None:
            return
        if held is not structure:
            self._spare = (structure, [])
        self._spare[1].append(symbolic)

    def init(self, free: np.ndarray) -> "CholeskyPlan":
        return CholeskyPlan(np.asarray(free, bool), self)


class Analysis:
    """One pattern's analysis: where A_ff's lower triangle sits in its CSC data, a CHOLMOD
    matrix of that pattern to load values into, and the shared symbolic factorisation."""

    def __init__(self, block):
        col = np.repeat(np.arange(block.shape[1]), np.diff(block.indptr))
        lower = np.flatnonzero(block.indices >= col)
        rows, cols = block.indices[lower], col[lower]
        probe = _sparse(np.arange(lower.size, dtype=float), rows.tolist(), cols.tolist(),
                        block.shape)
        self.lower = lower[np.asarray(probe.V, dtype=np.intp).ravel()]  # CHOLMOD's order
        self.matrix = probe
        self.shared = None
        self.generation = 0
        self.factor_nbytes = None

    def load(self, block) -> None:
        self.matrix.V = _dense(block.data[self.lower])

    def measure(self) -> None:
        """Set :attr:`factor_nbytes` (12 bytes per entry of L) from a throwaway factor of the
        loaded matrix: reading a factor's entries spoils it for solves."""
        factor = _cholmod.symbolic(self.matrix)
        _cholmod.numeric(self.matrix, factor)
        self.factor_nbytes = 12 * len(_cholmod.getfactor(factor).V)


@dataclass(frozen=True)
class CholeskyPlan(Plan):
    solver: SparseCholesky
    analyses: dict = field(default_factory=dict, compare=False)

    def factor(self, A, keep: bool = False) -> "CholeskyFactor":
        """The Cholesky factor of A's free block; one that is not positive definite raises
        SolveError.  ``keep``: the factor stays valid after later ones (own analysis)."""
        system = self.system(A)
        block = system.free_block
        analysis = self.analyses.get(system.structure) if system.structure is not None else None
        if analysis is None:
            analysis = Analysis(block)
            if system.structure is not None:
                self.analyses.clear()  # a pattern that grew replaces the old one
                self.analyses[system.structure] = analysis
        analysis.load(block)
        if keep:
            symbolic = (self.solver._take_spare(system.structure)
                        or _cholmod.symbolic(analysis.matrix))
        else:
            if analysis.shared is None:
                analysis.shared = _cholmod.symbolic(analysis.matrix)
            symbolic = analysis.shared
        generation = None
        if symbolic is analysis.shared:  # every earlier factor sharing it is now stale
            analysis.generation += 1
            generation = analysis.generation
        try:
            _cholmod.numeric(analysis.matrix, symbolic)
        except ArithmeticError:
            raise SolveError("the step matrix is not positive definite (Cholesky failed): "
                             "stiff compression or contact at this dt; reduce dt") from None
        if generation is None and analysis.factor_nbytes is None:
            analysis.measure()
        return CholeskyFactor(system, self, symbolic, analysis, generation)


class CholeskyFactor(Factored):
    def __init__(self, system, plan, factor, analysis, generation):
        super().__init__(system, plan)
        self.factor, self.analysis, self.generation = factor, analysis, generation

    def __del__(self):
        if self.generation is None:  # a kept factor: its analysis serves the next pass
            self.plan.solver._give_back(self.system.structure, self.factor)

    @property
    def nbytes(self) -> int:
        """An estimate: 12 bytes per entry of L (known after the pattern's first kept
        factor; 0 before)."""
        return self.analysis.factor_nbytes or 0

    def _solve_free(self, rhs, transpose: bool, x0, tol):
        if self.generation is not None and self.generation != self.analysis.generation:
            raise RuntimeError("this Cholesky factor was overwritten by a later factorisation "
                               "of the same plan; factor(A, keep=True) keeps one")
        x = _dense(rhs)
        _cholmod.solve(self.factor, x)
        x = np.asarray(x).ravel()
        return x, SolveInfo(0, None)  # Cholesky is backward stable: no residual check
