"""Linear solvers for the implicit step ``A dv = b`` with some components held fixed, as
objects in the manner of lineax.

A solver object holds settings only.  ``solver.init(free)`` does the analysis that holds
for every matrix of a simulation (the free and constrained index sets; a fill-reducing
ordering is computed per factorisation today); ``plan.factor(A)`` prepares one matrix (a
factorisation, or CG's preconditioner); the result solves ``A x = b`` and ``A^T x = b``
and reports a :class:`SolveInfo` with every solution, so the transpose solve of an adjoint
can reuse what the forward solve built.

Every solve is of the reduced system: constrained (pinned, attached) components take
their prescribed value ``z`` and the free ones solve ``A_ff x_f = b_f - A_fc z_c``.

* :class:`ModifiedPCG` ("cg"): the modified preconditioned conjugate gradient of Baraff and
  Witkin (1998), a filter zeroing the constrained components of every search direction,
  Jacobi preconditioning; for symmetric positive definite A (it refuses others as it
  meets them).
* :class:`SparseLU` ("direct"): SuperLU on the free block; any non-singular A.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


class SolveError(RuntimeError):
    """The linear solve failed: not converged, not positive definite, or singular."""


@dataclass(frozen=True)
class SolveInfo:
    """How a solve went: ``iterations`` (0 for a direct solve) and the final relative
    ``residual`` of the free block (CG: in its preconditioner's norm)."""

    iterations: int
    residual: float


@dataclass(frozen=True)
class Plan:
    """What a solver keeps for every matrix of one simulation: the free components."""

    free: np.ndarray

    @property
    def free_index(self) -> np.ndarray:
        return np.flatnonzero(self.free)

    @property
    def fixed_index(self) -> np.ndarray:
        return np.flatnonzero(~self.free)


def _start(b, free, z):
    """The solution's constrained part: ``z`` there (zero without z), zero elsewhere."""
    return np.zeros_like(b) if z is None else np.where(free, 0.0, z)


class ModifiedPCG:
    """Baraff-Witkin modified PCG; converged when ``|r|_P^-1 <= tol |b_f|_P^-1``.

    ``maxiter`` defaults to ten times the system's size.
    """

    name = "cg"

    def __init__(self, tol: float = 1e-10, maxiter: int | None = None):
        if not (0 < tol < 1):
            raise ValueError(f"CG's relative tolerance must be in (0, 1), got {tol}")
        self.tol, self.maxiter = tol, maxiter

    def init(self, free: np.ndarray) -> "PCGPlan":
        return PCGPlan(np.asarray(free, bool), self)


@dataclass(frozen=True)
class PCGPlan(Plan):
    solver: ModifiedPCG

    def factor(self, A) -> "JacobiPreconditioned":
        """The matrix with its Jacobi preconditioner; refuses a non-positive diagonal."""
        diag = A.diagonal()
        if np.any(diag[self.free] <= 0):
            raise SolveError("the step matrix has a non-positive diagonal entry, so it is not "
                             "positive definite (stiff compression or contact at this dt); "
                             "reduce dt or use solver='direct'")
        return JacobiPreconditioned(A, np.where(self.free, 1.0 / diag, 0.0), self)


@dataclass(frozen=True)
class JacobiPreconditioned:
    A: sp.spmatrix
    inv_p: np.ndarray
    plan: PCGPlan

    def solve(self, b, z=None, *, x0=None, tol: float | None = None):
        """``(x, SolveInfo)`` of ``A x = b`` with ``x = z`` on the constrained components;
        ``x0`` warm-starts the free ones, ``tol`` overrides the solver's."""
        solver, free = self.plan.solver, self.plan.free
        tol = solver.tol if tol is None else tol
        A, inv_p = self.A, self.inv_p
        filt = free.astype(float)
        x = _start(b, free, z)
        if x0 is not None:
            x = np.where(free, x0, x)
        fb = filt * b
        delta0 = fb @ (inv_p * fb)
        r = filt * (b - A @ x)
        c = inv_p * r
        delta = r @ c
        maxiter = solver.maxiter or 10 * b.size
        it = 0
        while delta > tol ** 2 * delta0 and delta0 > 0:
            if it >= maxiter:
                raise SolveError(f"modified PCG did not converge in {maxiter} iterations "
                                 f"(relative residual {np.sqrt(delta / delta0):.2e}); reduce "
                                 "dt or the stiffness, or use solver='direct'")
            q = filt * (A @ c)
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
            c *= filt
            it += 1
        return x, SolveInfo(it, float(np.sqrt(delta / delta0)) if delta0 > 0 else 0.0)

    def solve_transpose(self, b, z=None, *, x0=None, tol: float | None = None):
        """``A^T x = b``: A is symmetric here, so the same solve."""
        return self.solve(b, z, x0=x0, tol=tol)


class SparseLU:
    """SuperLU on the free block.  ``symmetric=True`` (a symmetric A) uses its symmetric
    mode with a minimum-degree ordering of ``A + A^T``, faster than the default column
    ordering on cloth."""

    name = "direct"

    def __init__(self, symmetric: bool = True):
        self.symmetric = symmetric

    def init(self, free: np.ndarray) -> "LUPlan":
        return LUPlan(np.asarray(free, bool), self)


@dataclass(frozen=True)
class LUPlan(Plan):
    solver: SparseLU

    def factor(self, A) -> "LUFactors":
        """SuperLU factors of A's free block; a singular A raises SolveError."""
        A = sp.csr_matrix(A)
        block = A[self.free_index][:, self.free_index].tocsc()
        try:
            lu = (spla.splu(block, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
                  if self.solver.symmetric else spla.splu(block))
        except RuntimeError as err:  # SuperLU: "Factor is exactly singular"
            raise SolveError(f"the step matrix is singular ({err})") from err
        return LUFactors(lu, A, block, self)


@dataclass(frozen=True)
class LUFactors:
    lu: spla.SuperLU
    A: sp.csr_matrix
    block: sp.csc_matrix  # A_ff, factored
    plan: LUPlan

    def _solve(self, b, z, trans: str):
        plan = self.plan
        x = _start(b, plan.free, z)
        fi, ci = plan.free_index, plan.fixed_index
        rhs = b[fi]
        if z is not None and ci.size:  # move the prescribed part to the right-hand side
            A = self.A if trans == "N" else self.A.T.tocsr()
            rhs = rhs - A[fi][:, ci] @ x[ci]
        x[fi] = self.lu.solve(rhs, trans=trans)
        block = self.block if trans == "N" else self.block.T
        scale = np.linalg.norm(rhs)
        residual = np.linalg.norm(block @ x[fi] - rhs) / scale if scale > 0 else 0.0
        return x, SolveInfo(0, float(residual))

    def solve(self, b, z=None, *, x0=None, tol=None):
        """``(x, SolveInfo)`` of ``A x = b`` with ``x = z`` on the constrained components
        (``x0`` and ``tol`` are for iterative solvers and unused)."""
        return self._solve(b, z, "N")

    def solve_transpose(self, b, z=None, *, x0=None, tol=None):
        """``A^T x = b`` with the same factors."""
        return self._solve(b, z, "T")


SOLVERS = {"cg": ModifiedPCG, "direct": SparseLU}


def linear_solver(solver, **options):
    """A solver object from a name in :data:`SOLVERS` (with ``options``) or an object."""
    if isinstance(solver, str):
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {sorted(SOLVERS)} or a solver object, "
                             f"got {solver!r}")
        return SOLVERS[solver](**options)
    if not callable(getattr(solver, "init", None)):
        raise TypeError(f"a linear solver needs an init(free) method, got {solver!r}")
    return solver
