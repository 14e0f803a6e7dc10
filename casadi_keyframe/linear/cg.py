"""Modified preconditioned conjugate gradients (Baraff and Witkin, 1998), for symmetric
positive definite A: their filter, which keeps the constrained components at their
prescribed values, is the solve of the free block with the constrained part moved to the
right-hand side, which is what runs here, with a Jacobi preconditioner.  It refuses an
operator that is not positive definite as soon as it meets the evidence.  Needs memory for
the matrix only, so it is the solver for systems too large to factor."""
from __future__ import annotations

import numpy as np

from .system import Factored, Plan, SolveError, SolveInfo


class ModifiedPCG:
    """Modified PCG; converged when ``|r|_P^-1 <= tol |b_f|_P^-1`` (P the preconditioner).

    ``maxiter`` defaults to ten times the free block's size.
    """

    name = "cg"

    def __init__(self, tol: float = 1e-10, maxiter: int | None = None):
        if not (0 < tol < 1):
            raise ValueError(f"CG's relative tolerance must be in (0, 1), got {tol}")
        self.tol, self.maxiter = tol, maxiter

    def init(self, free: np.ndarray) -> "PCGPlan":
        return PCGPlan(free, self)


class PCGPlan(Plan):
    worth_keeping = False  # reuse saves one assembly, next to hundreds of iterations

    def __init__(self, free: np.ndarray, solver: ModifiedPCG):
        super().__init__(free)
        self.solver = solver

    def factor(self, A, keep: bool = False) -> "JacobiPreconditioned":
        """The matrix with its Jacobi preconditioner; refuses a non-positive diagonal.
        (``keep`` is for factorisations: every result of this plan can be kept.)"""
        system = self.system(A)
        diag = system.free_block.diagonal()
        if np.any(diag <= 0):
            raise SolveError("the step matrix has a non-positive diagonal entry, so it is not "
                             "positive definite (stiff compression or contact at this dt); "
                             "reduce dt or use solver='direct'")
        return JacobiPreconditioned(system, self, 1.0 / diag)


class JacobiPreconditioned(Factored):
    def __init__(self, system, plan, inv_p):
        super().__init__(system, plan)
        self.inv_p = inv_p
        self.operator = system.free_block.tocsr()  # A_ff is symmetric: same as its CSC
        self.nbytes = inv_p.nbytes + self.operator.data.nbytes + self.operator.indices.nbytes

    def _solve_free(self, b, transpose: bool, x0, tol):
        solver = self.plan.solver
        tol = solver.tol if tol is None else tol
        A, inv_p = self.operator, self.inv_p
        x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
        delta0 = b @ (inv_p * b)
        r = b - A @ x
        c = inv_p * r
        delta = r @ c
        maxiter = solver.maxiter or 10 * b.size
        it = 0
        while delta > tol ** 2 * delta0 and delta0 > 0:
            if it >= maxiter:
                raise SolveError(f"modified PCG did not converge in {maxiter} iterations "
                                 f"(relative residual {np.sqrt(delta / delta0):.2e}); reduce "
                                 "dt or the stiffness, or use solver='direct'")
            q = A @ c
            curvature = c @ q
            if curvature <= 0:
                raise SolveError("modified PCG met a direction of non-positive curvature: the "
                                 "step matrix is not positive definite (stiff compression or "
                                 "contact at this dt); reduce dt or use solver='direct'")
            alpha = delta / curvature
            x += alpha * c
            r -= alpha * q
            s = inv_p * r
            delta, old = r @ s, delta
            c = s + (delta / old) * c
            it += 1
        if delta0 == 0:
            x[:] = 0.0
        return x, SolveInfo(it, float(np.sqrt(delta / delta0)) if delta0 > 0 else 0.0)
