r"""The SQP's step system solved without forming it, for large sheets (:mod:`.sqp`).

The step's matrix ``B = J^T Q J + Jr^T Jr + sum_k lambda_k C_k + mu D`` is applied as an
operator (:class:`StepOperator`: ``J`` the control Jacobian the transcription assembles,
one sparse matrix of a fixed pattern) and solved by preconditioned conjugate gradients
(:func:`conjugate_gradients`, every right-hand side at once), so no product of Jacobians
is formed and the memory stays that of ``J``.  A solve stops on its relative residual or,
earlier, once the quadratic model has stopped falling (an inexact step in a trust region:
every conjugate gradient iterate lowers the model, and the SQP predicts its decrease from
the step it takes).

Preconditioners (``preconditioner``):

* ``"frames"`` (the default): block Jacobi in time, each frame's diagonal block of ``B``
  (one frame's size, sparse) formed and factored (:class:`FrameBlocks`);
* ``"steps"``: the per-step matrices the library factors.  With every free component
  controlled, ``J`` is square and block lower triangular in time, step n's block in frame
  n+1 the linearized step's own matrix ``A_n / dt^2``; ``(L^T Q L)^-1`` with ``L = J +
  beta G`` (``G^T G`` the damping metric's inertial part, :func:`_lower_root`) is applied
  by block substitution, one sparse LU per step (:class:`StepPreconditioner`).  Exact for
  the rest state, but the substitution simulates the linearized motion, which grows where
  the sheet buckles: on a moved sheet it is useless (docs/search_notes.md);
* ``"jacobi"`` (the diagonal) and ``"none"``, for comparison.

:class:`LinearChoice` picks the direct factor (:class:`~.sqp.Factor`) or this solve by the
number of unknowns (``linear="auto"``) or as asked.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ... import progress
from ...interrupts import check

LINEAR = ("auto", "direct", "iterative")
AUTO_FACTOR = 8e7  # unknowns times one frame's above which linear="auto" solves iteratively:
# the factor frame after frame holds about that many non-zeros (docs/search_notes.md)
CG_TOL = 1e-6  # relative residual at which conjugate gradients stop
CG_MAXITER = 400  # conjugate gradient iterations per solve at most
CG_SETTLE = 1e-3  # stop once the model falls by less than this share over WINDOW iterations
WINDOW = 10
PRECONDITIONERS = ("steps", "frames", "jacobi", "none")


@dataclass
class LinearChoice:
    """How the step's system is solved: ``linear`` one of :data:`LINEAR`; ``auto`` is
    iterative where the unknowns times one frame's unknowns (the size of the factor frame
    after frame, about) exceed :data:`AUTO_FACTOR`."""

    linear: str = "auto"
    tol: float = CG_TOL
    maxiter: int = CG_MAXITER
    preconditioner: str = "frames"
    settle: float = CG_SETTLE

    def __post_init__(self):
        if self.linear not in LINEAR:
            raise ValueError(f"linear={self.linear!r}: give one of {', '.join(LINEAR)}")
        if self.preconditioner not in PRECONDITIONERS:
            raise ValueError(f"preconditioner={self.preconditioner!r}: give one of "
                             f"{', '.join(PRECONDITIONERS)}")

    def iterative(self, size: int, frame: int) -> bool:
        """Whether ``size`` unknowns, ``frame`` of them per frame, are solved iteratively."""
        return self.linear == "iterative" or (self.linear == "auto"
                                              and size * frame > AUTO_FACTOR)


class StepOperator:
    """``p -> (J^T Q J + Jr^T Jr + sum_k lambda_k C_k) p + mu D p`` without forming it;
    :meth:`model` is the part without the damping (the model's curvature)."""

    def __init__(self, J, Q, Jr, weighted, mu: float, metric):
        self.J, self.JT = sp.csr_matrix(J), sp.csr_matrix(J.T)
        self.Q, self.Jr, self.mu, self.metric = Q, sp.csr_matrix(Jr), mu, metric
        self.JrT = sp.csr_matrix(self.Jr.T)
        self.weighted = [(float(l), C) for l, C in weighted if l > 0]
        self.shape = (self.J.shape[1],) * 2

    def model(self, p) -> np.ndarray:
        out = self.JT @ (self.Q @ (self.J @ p))
        if self.Jr.shape[0]:
            out += self.JrT @ (self.Jr @ p)
        for l, C in self.weighted:
            out += l * (C @ p)
        return out

    def __call__(self, p) -> np.ndarray:
        return self.model(p) + self.mu * (self.metric @ p)

    def diagonal(self) -> np.ndarray:
        """The diagonal of the operator (the Jacobi preconditioner's)."""
        d = np.asarray(self.J.multiply(self.Q @ self.J).sum(axis=0)).ravel()
        d += np.asarray(self.Jr.multiply(self.Jr).sum(axis=0)).ravel()
        for l, C in self.weighted:
            d += l * C.diagonal()
        return d + self.mu * self.metric.diagonal()

    def formed(self) -> sp.csr_matrix:
        """The matrix itself (for checks on small problems only)."""
        H = self.J.T @ self.Q @ self.J + self.Jr.T @ self.Jr + self.mu * self.metric
        for l, C in self.weighted:
            H = H + l * C
        return sp.csr_matrix(H)


class StepPreconditioner:
    """The module docstring's ``"steps"``, ``(L^T Q L)^-1`` for a transcription ``tr`` whose control
    Hessian is ``Q`` and whose damping metric weighs a force by ``weight`` and a component by
    ``scale`` (:func:`~.sqp.inertial_scale`): :meth:`update`
    at each iterate (``J``, ``mu``), then called on residuals ``(size,)`` or ``(size, k)``."""

    def __init__(self, tr, Q, weight: float, metric, scale):
        self.N, self.nf = tr.N, tr.nf
        idx = tr.problem.controls.idx
        comps = (idx[:, None] * 3 + np.arange(3)).ravel()
        width = comps.size
        row = -np.ones(3 * tr.n, np.int64)
        row[comps] = np.arange(width)
        within = row[tr.free_flat]
        self.usable = bool(np.all(within >= 0))
        self.rows = (np.arange(tr.N)[:, None] * width + within[None, :]).ravel()
        q = np.asarray(sp.csr_matrix(Q).diagonal())[self.rows] if self.usable else None
        self.q = q
        self.weight = weight
        self.S = sp.kron(_lower_root(metric, tr.N, tr.nf, weight * scale[0] ** 2),
                         sp.diags(scale)).tocsr()
        self.blocks = self.lower = self.upper = None

    def update(self, J, mu: float) -> None:
        """Factor the per-step blocks of ``L = J + beta G`` at this iterate (``beta^2 G^T
        G`` the damping's part of ``B`` over ``Q``'s scale)."""
        beta = np.sqrt(mu * self.weight / float(np.mean(self.q)))
        L = (sp.csr_matrix(J)[self.rows] + beta * self.S).tocsr()
        nf, N = self.nf, self.N
        self.blocks, self.lower, self.upper = [], [], []
        LT = L.T.tocsr()
        for n in range(N):
            rows = slice(n * nf, (n + 1) * nf)
            band = L[rows]
            self.blocks.append(splu(band[:, rows].tocsc()))
            self.lower.append(band[:, max(n - 2, 0) * nf:n * nf])
            self.upper.append(LT[rows][:, (n + 1) * nf:min(n + 3, N) * nf])

    def __call__(self, r) -> np.ndarray:
        nf, N = self.nf, self.N
        y = np.empty_like(r)
        for n in reversed(range(N)):  # L^T y = r, backwards in time
            rhs = r[n * nf:(n + 1) * nf]
            if n + 1 < N:
                rhs = rhs - self.upper[n] @ y[(n + 1) * nf:min(n + 3, N) * nf]
            y[n * nf:(n + 1) * nf] = self.blocks[n].solve(rhs, trans="T")
        y = y / (self.q if y.ndim == 1 else self.q[:, None])
        x = np.empty_like(r)
        for n in range(N):  # L x = y, forwards in time
            rhs = y[n * nf:(n + 1) * nf]
            if n:
                rhs = rhs - self.lower[n] @ x[max(n - 2, 0) * nf:n * nf]
            x[n * nf:(n + 1) * nf] = self.blocks[n].solve(rhs)
        return x


def _lower_root(metric, N: int, nf: int, unit: float) -> sp.csr_matrix:
    """The lower triangular ``G`` (banded as the metric) with ``G^T G`` the damping
    metric's time part (its first component's ``N x N`` entries over ``unit``), so that
    ``G (x) diag(scale)`` has the control Jacobian's block lower triangular shape."""
    Dt = sp.csr_matrix(metric)[0::nf][:, 0::nf].toarray() / unit
    flip = np.linalg.cholesky(Dt[::-1, ::-1])  # lower: reversed, its transpose is G
    G = flip.T[::-1, ::-1]
    G[np.abs(G) < 1e-14 * np.abs(G).max()] = 0.0
    return sp.csr_matrix(G)


class FrameBlocks:
    """Block Jacobi in time: the inverse of the step matrix's diagonal blocks, one per frame
    (each frame's ``nf x nf`` block formed from the operator's parts and factored)."""

    def __init__(self, operator: StepOperator, N: int, nf: int):
        self.N, self.nf = N, nf
        J = operator.J.tocsc()
        QJ = sp.csc_matrix(operator.Q @ operator.J)
        Jr = operator.Jr.tocsc()
        metric = sp.csc_matrix(operator.metric)
        weighted = [(l, sp.csc_matrix(C)) for l, C in operator.weighted]
        self.blocks = []
        for n in range(N):
            cols = slice(n * nf, (n + 1) * nf)
            Jn = J[:, cols]
            rows = np.unique(Jn.indices)
            B = Jn[rows].T @ QJ[:, cols][rows]
            if Jr.shape[0]:
                B = B + Jr[:, cols].T @ Jr[:, cols]
            for l, C in weighted:
                B = B + l * C[:, cols][cols]
            B = B + operator.mu * metric[:, cols][cols]
            self.blocks.append(splu(sp.csc_matrix(B)))

    def __call__(self, r) -> np.ndarray:
        x = np.empty_like(r)
        nf = self.nf
        for n, lu in enumerate(self.blocks):
            x[n * nf:(n + 1) * nf] = lu.solve(np.ascontiguousarray(r[n * nf:(n + 1) * nf]))
        return x


@dataclass
class Solves:
    """What the iterative solves of one SQP iteration did: conjugate gradient iterations
    per call (the most over its right-hand sides)."""

    iterations: list


class IterativeSystem:
    """The step's system at one iterate, solved by :func:`conjugate_gradients`:
    ``solve(rhs)``, ``curvature(p)`` (the model's matrix times ``p``) and ``solves``."""

    def __init__(self, operator: StepOperator, precondition, choice: LinearChoice):
        self.operator, self.precondition, self.choice = operator, precondition, choice
        self.solves = Solves([])

    def solve(self, rhs) -> np.ndarray:
        x, its = conjugate_gradients(self.operator, np.asarray(rhs, float), self.precondition,
                                     tol=self.choice.tol, maxiter=self.choice.maxiter,
                                     settle=self.choice.settle)
        self.solves.iterations.append(its)
        return x

    def curvature(self, p) -> np.ndarray:
        return self.operator.model(p)


def iterative_system(sqp, x, lam, mu: float, choice: LinearChoice) -> IterativeSystem:
    """The step's system of :class:`~.sqp.PositionSQP` ``sqp`` at its point ``x``."""
    operator = StepOperator(x.J, sqp.Q, x.Jr, zip(lam, sqp.C), mu, sqp.metric)
    kind = choice.preconditioner
    if kind == "steps":
        if getattr(sqp, "_preconditioner", None) is None:
            sqp._preconditioner = StepPreconditioner(sqp.tr, sqp.Q, sqp.weight, sqp.metric,
                                                     sqp.scale)
        pre = sqp._preconditioner
        if pre.usable:
            pre.update(x.J, mu)
        else:
            kind = "jacobi"
    if kind == "frames":
        pre = FrameBlocks(operator, sqp.tr.N, sqp.tr.nf)
    elif kind == "jacobi":
        d = operator.diagonal()
        pre = _scaled(1.0 / d)
    elif kind == "none":
        pre = None
    return IterativeSystem(operator, pre, choice)


def _scaled(inverse):
    return lambda r: r * (inverse if r.ndim == 1 else inverse[:, None])


def conjugate_gradients(apply, b, precondition=None, *, tol: float = CG_TOL,
                        maxiter: int = CG_MAXITER, settle: float = 0.0):
    """``(x, iterations)`` with ``apply(x) ~ b`` for a symmetric positive definite
    operator, every column of ``b`` at once, each stopped once its residual is ``tol`` of
    its right-hand side's, once the quadratic model ``x^T B x / 2 - b^T x`` has fallen by
    less than ``settle`` of its decrease so far over the last :data:`WINDOW` iterations
    (an inexact solve, Steihaug-Toint's: every iterate lowers the model), or at
    ``maxiter``.  Each
    iteration is a safe point (:func:`~casadi_keyframe.interrupts.check`) and advances a
    progress task.  A column whose search direction shows non-positive curvature (the
    operator positive definite only to round-off) keeps its last iterate."""
    B = b.reshape(b.shape[0], -1)
    X = np.zeros_like(B)
    R = B.copy()
    norm_b = np.linalg.norm(B, axis=0)
    active = norm_b > 0
    Z = R if precondition is None else precondition(R)
    P = Z.copy()
    rz = np.einsum("ij,ij->j", R, Z)
    its = 0
    gained = np.zeros((B.shape[1], WINDOW + 1))  # model decreases of the last iterations
    total = np.zeros(B.shape[1])
    if B.shape[1] == 1:
        single = apply
        apply = lambda p: single(p[:, 0])[:, None]  # noqa: E731
    with progress.task("conjugate gradients", maxiter, "iterations", exact=False):
        while its < maxiter:
            active &= np.linalg.norm(R, axis=0) > tol * norm_b
            if its > WINDOW:  # the model stopped falling: the rest is not worth its cost
                active &= gained.sum(axis=1) > settle * total
            if not active.any():
                break
            check()
            cols = np.flatnonzero(active)
            AP = apply(P[:, cols])
            curv = np.einsum("ij,ij->j", P[:, cols], AP)
            flat = curv <= 0  # round-off: that column keeps its iterate (Steihaug-Toint)
            if flat.any():
                active[cols[flat]] = False
                cols, AP, curv = cols[~flat], AP[:, ~flat], curv[~flat]
                if not cols.size:
                    break
            alpha = rz[cols] / curv
            gained[cols, its % (WINDOW + 1)] = 0.5 * alpha * rz[cols]
            total[cols] += 0.5 * alpha * rz[cols]
            X[:, cols] += alpha * P[:, cols]
            R[:, cols] -= alpha * AP
            Zc = R[:, cols] if precondition is None else precondition(R[:, cols])
            rz_new = np.einsum("ij,ij->j", R[:, cols], Zc)
            P[:, cols] = Zc + (rz_new / rz[cols]) * P[:, cols]
            rz[cols] = rz_new
            its += 1
            progress.advance()
    return X.reshape(b.shape), its
