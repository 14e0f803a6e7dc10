"""SuperLU (scipy) on the free block: the direct solver that needs no package beyond scipy.

For a symmetric positive definite A (``symmetric=True``) it runs in SuperLU's symmetric
mode with a minimum-degree ordering of ``A + A^T`` and no pivoting off the diagonal
(``DiagPivotThresh=0``): an SPD matrix needs none, and SuperLU's default threshold pivots on
cloth step matrices (SPD but not diagonally dominant), which multiplies the fill and the time
of a factorisation many times over.  ``symmetric=False`` keeps SuperLU's defaults (partial
pivoting, column ordering) for any non-singular A.  scipy's SuperLU cannot reuse an
analysis, so every matrix is analysed afresh.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from .system import Factored, Plan, SolveError, SolveInfo


class SparseLU:
    """SuperLU on the free block (module docstring)."""

    name = "direct"

    def __init__(self, symmetric: bool = True):
        self.symmetric = symmetric

    def init(self, free: np.ndarray) -> "LUPlan":
        return LUPlan(free, self)


class LUPlan(Plan):
    def __init__(self, free: np.ndarray, solver: SparseLU):
        super().__init__(free)
        self.solver = solver

    def factor(self, A, keep: bool = False) -> "LUFactors":
        """SuperLU factors of A's free block; a singular A raises SolveError.  (Every
        factorisation is its own, so ``keep`` changes nothing.)"""
        system = self.system(A, self.solver.symmetric)
        options = ({"permc_spec": "MMD_AT_PLUS_A",
                    "options": {"SymmetricMode": True, "DiagPivotThresh": 0.0}}
                   if self.solver.symmetric else {})
        try:
            lu = spla.splu(system.free_block, **options)
        except RuntimeError as err:  # SuperLU: "Factor is exactly singular"
            raise SolveError(f"the step matrix is singular ({err})") from err
        return LUFactors(system, self, lu)


class LUFactors(Factored):
    def __init__(self, system, plan, lu):
        super().__init__(system, plan)
        self.lu = lu

    @property
    def nbytes(self) -> int:
        return 12 * (self.lu.nnz + self.lu.shape[0])

    def _solve_free(self, rhs, transpose: bool, x0, tol):
        x = self.lu.solve(rhs, trans="T" if transpose else "N")
        residual = self.residual(x, rhs, transpose)
        if not np.isfinite(residual) or (self.plan.solver.symmetric and residual > 1e-6):
            raise SolveError(f"the factorisation without pivoting is inaccurate (relative "
                             f"residual {residual:.1e}): the matrix is not positive definite; "
                             "reduce dt or use SparseLU(symmetric=False)")
        return x, SolveInfo(0, residual)
