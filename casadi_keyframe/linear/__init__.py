"""Linear solvers for the implicit step ``A dv = b`` with some components held fixed, as
objects in the manner of lineax.

A solver holds settings only; ``solver.init(free)`` gives a plan that keeps the state
(pattern analyses per pattern) and ``plan.factor(A, keep=False)`` prepares one matrix, which
solves ``A x = b`` and ``A^T x = b`` (the adjoint reuses what the forward pass built).

* :class:`SparseCholesky` ("cholmod"): CHOLMOD's supernodal Cholesky (cvxopt); SPD A.
* :class:`SparseLU` ("direct"): scipy's SuperLU; SPD, or any non-singular A.
* :class:`ModifiedPCG` ("cg"): Baraff-Witkin's modified PCG, Jacobi preconditioned; SPD A.
* :class:`Auto` ("auto"): one of those by the system's size and what is installed.
"""
from __future__ import annotations

import numpy as np

from .cg import JacobiPreconditioned, ModifiedPCG, PCGPlan
from .cholesky import CholeskyFactor, CholeskyPlan, SparseCholesky, available as cholmod_available
from .lu import LUFactors, LUPlan, SparseLU
from .system import Factored, Plan, SolveError, SolveInfo, System

__all__ = ["Auto", "CholeskyFactor", "CholeskyPlan", "Factored", "JacobiPreconditioned",
           "LUFactors", "LUPlan", "ModifiedPCG", "PCGPlan", "Plan", "SOLVERS", "SolveError",
           "SolveInfo", "SparseCholesky", "SparseLU", "System", "cholmod_available",
           "linear_solver"]


class Auto:
    """Picks a solver per free-block size (:meth:`choose`, the same object for the same size):
    CHOLMOD when cvxopt is installed and the free block has at most ``cholmod_max`` unknowns,
    else SuperLU up to ``lu_max`` unknowns, else modified PCG (with ``tol``), whose memory is
    the matrix's."""

    name = "auto"

    def __init__(self, tol: float = 1e-10, cholmod_max: int = 400_000, lu_max: int = 40_000):
        self.tol, self.cholmod_max, self.lu_max = tol, cholmod_max, lu_max
        self._chosen: dict[int, object] = {}

    def choose(self, size: int):
        """The solver for a free block of ``size`` unknowns (kept: asked again, the same)."""
        if size not in self._chosen:
            if cholmod_available() and size <= self.cholmod_max:
                self._chosen[size] = SparseCholesky()
            elif size <= self.lu_max:
                self._chosen[size] = SparseLU()
            else:
                self._chosen[size] = ModifiedPCG(self.tol)
        return self._chosen[size]

    def init(self, free: np.ndarray) -> Plan:
        return self.choose(int(np.count_nonzero(free))).init(free)


SOLVERS = {"auto": Auto, "cholmod": SparseCholesky, "direct": SparseLU, "cg": ModifiedPCG}


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
