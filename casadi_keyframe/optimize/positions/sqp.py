r"""Least effort under the goal, in positions: a sequential quadratic programme with the
effort's Gauss-Newton matrix, in a trust region.

At an iterate z, with the controls ``u(z)`` (:class:`~.transcription.Transcription`), their
Jacobian ``J`` and the control terms' constant Hessian ``Q``, each step solves

    minimise  g^T p + 1/2 p^T (J^T Q J + J_r^T J_r + sum_k lambda_k C_k + mu D) p
    subject to c_k + a_k^T p <= (1 - theta) c_k if c_k > 0, else 0   (the goal, :mod:`.goal`)

(``g = J^T Q u + s J_r^T r``: the effort's gradient, its strain penalty's part (residuals
``r``, :mod:`.strain`) weighed by ``s = theta`` until the goal holds, then by 1; ``C_k`` the
constraints' constant Hessians and
``lambda_k`` their last multipliers; ``D`` :func:`damping_metric`, weighed as the control
cost weighs a force, so ``mu`` is a pure number): one sparse Cholesky factorisation, one
solve per constraint and a tiny active-set problem for the multipliers. ``mu`` and ``theta``
(the share of a violated constraint one step removes) make a trust region: the linear model
of the forces holds only for small moves where the cloth buckles or turns (a buckling
sheet's positions move far for forces that change little to first order, the controls'
sensitivity seen from the other side). The trial is corrected for the stiff springs
(:mod:`.restore`) and, where it breaks a keyframe's bound beyond the linear model (the
misses are quadratic in the positions), by a second-order correction on the same factor; a
plan the model's own checks refuse (a torn cloth) is never kept; it is kept when the exact
l1 merit ``effort + sigma sum max(c_k, 0)`` falls by a share of what the model predicts
(``sigma`` at least twice the multipliers, the QP's and their least-squares estimate). Then
``mu`` halves and ``theta`` doubles, up to :data:`THETA_MAX`; else ``mu`` grows (fourfold,
sixteenfold when the merit rose) and ``theta`` halves if the goal's own model failed or the
merit rose by more than the model's decrease (the goal's demand keeps a step long whatever
``mu``).
``theta`` never exceeds :data:`THETA_MAX` < 1, so the goal is approached over several steps,
each trading it against the effort: a step that removes the whole violation at once commits
the motion to the first way the linear model finds to meet the goal (from a sheet held
still: held up against gravity all along and folded in the last frames), a local optimum of
far more effort than the motions a gradual approach finds. It ends when the constraints hold
(to :data:`HELD` of their bounds) and the effort has changed by less than ``tol`` (relative)
over the last :data:`SETTLED` kept steps, at ``maxiter``, when asked to stop, or when no
step is kept at the largest damping.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

try:
    from cvxopt import cholmod, matrix, spmatrix
except ImportError:  # SuperLU instead (slower, same answer)
    cholmod = None
from scipy.sparse.linalg import splu

from ...state import SimulationError
from .linear_solve import LinearChoice, iterative_system
from .restore import LengthRestoration
from .strain import StrainPenalty

ACCEPT = 0.1  # the share of the merit's predicted decrease a kept step must achieve
MU_START, MU_MIN, MU_MAX = 1e3, 1e-10, 1e12  # damping, in the metric D
THETA_MAX, THETA_MIN = 0.5, 1e-3  # the share of the goal's violation a step removes
SETTLED = 3  # kept steps over which the effort must have settled
HELD = 1e-3  # a constraint within this share of its bound beyond it counts as held: with
# THETA_MAX < 1 a step asks for a share of a violation, which then shrinks but never ends
POSITION_SHARE = 0.01  # of the damping metric's weight on the positions themselves


@dataclass
class Point:
    """An iterate: unknowns, controls, effort (control cost and strain penalty), its
    gradient in z, constraint values, and the Jacobians when asked."""

    z: np.ndarray
    u: np.ndarray
    effort: float
    gradient: np.ndarray
    c: np.ndarray
    J: object = None
    Jr: object = None  # the strain penalty's residuals' Jacobian
    r: object = None  # the strain penalty's residuals

    def violation(self) -> float:
        return float(np.sum(np.maximum(self.c, 0.0)))


@dataclass
class Progress:
    """What an iteration reports: the kept point's effort, violation and misses (m), the
    damping and share it ends with, the trial step's length, whether it was kept and the
    ratio of the merit's actual to predicted decrease."""

    iteration: int
    effort: float
    violation: float
    misses: list
    mu: float
    step: float
    kept: bool
    theta: float
    ratio: float


@dataclass
class Outcome:
    """How the search ended: its point, why (``converged``, ``maxiter``, ``stalled``,
    ``stopped``), its iterations and their reports."""

    z: np.ndarray
    reason: str  # "converged", "maxiter", "stalled", "stopped"
    iterations: int
    history: list = field(default_factory=list)


class Factor:
    """Sparse Cholesky of a symmetric positive definite matrix given whole (CHOLMOD through
    cvxopt, its analysis and the place of its lower triangle kept while the pattern holds;
    SuperLU without cvxopt).  The ordering is the unknowns' own, frame after frame: the
    step's matrix is banded in time, and its factor is smaller in that order than in
    CHOLMOD's fill-reducing one (``benchmarks/sqp_factor.py`` measures both)."""

    def __init__(self, natural: bool = True):
        self.natural = natural
        self._pattern = None
        self._symbolic = None
        self._matrix = None
        self._lower = None  # where the lower triangle's entries sit in the matrix's data

    def __call__(self, B):
        B = sp.csr_matrix(B)
        B.sum_duplicates()  # canonical: sorted, no duplicates (free when it already is)
        if cholmod is None:
            lu = splu(B.tocsc())
            return lambda rhs: lu.solve(np.asarray(rhs, float))
        key = (B.indptr.tobytes(), B.indices.tobytes())
        if key != self._pattern:
            self._analyse(B)
            self._pattern = key
        self._matrix.V = matrix(B.data[self._lower])
        cholmod.numeric(self._matrix, self._symbolic)
        factor, n = self._symbolic, B.shape[0]

        def solve(rhs):
            b = matrix(np.asarray(rhs, float).reshape(n, -1))
            cholmod.solve(factor, b)
            return np.asarray(b).reshape(np.shape(rhs))

        return solve

    def _analyse(self, B) -> None:
        """The analysis of ``B``'s pattern: a symmetric matrix's upper triangle by rows is
        its lower triangle by columns, loaded in CHOLMOD's order (read from a probe)."""
        n = B.shape[0]
        row = np.repeat(np.arange(n), np.diff(B.indptr))
        upper = np.flatnonzero(B.indices >= row)
        probe = spmatrix(matrix(np.arange(upper.size, dtype=float)),
                         matrix(B.indices[upper].astype(np.int64)),
                         matrix(row[upper].astype(np.int64)), (n, n))
        self._lower = upper[np.asarray(probe.V, dtype=np.intp).ravel()]
        self._matrix = probe
        order = {"p": matrix(np.arange(n, dtype=np.int64))} if self.natural else {}
        self._symbolic = cholmod.symbolic(probe, uplo="L", **order)


class PositionSQP:
    """The module docstring's search on a transcription ``tr`` under ``constraints``."""

    def __init__(self, tr, constraints, Q: sp.spmatrix, linear: LinearChoice | None = None):
        self.tr, self.constraints = tr, constraints
        self.linear = linear or LinearChoice()
        self.solves = None  # the last iteration's iterative solves (None: direct)
        self.Q = sp.csr_matrix(Q)
        self.C = [c.hessian() for c in constraints]
        self.held = HELD * np.array([abs(c.bound) for c in constraints])
        self.factor = Factor()
        self.evaluations = 0
        self.sigma = 0.0  # the merit's penalty weight, never lowered
        self.restore = LengthRestoration(tr)
        self.strain = StrainPenalty(tr)
        self._fill = None
        self.mu_used = None
        self.weight = float(np.mean(Q.diagonal()))
        self.scale = inertial_scale(tr)  # the metric's weight of a component
        self.metric = damping_metric(tr, self.weight)

    def point(self, z, jacobian: bool = True) -> Point:
        """The iterate at ``z`` (with the Jacobians when asked): its effort is the control
        cost plus the problem's strain penalty (:mod:`.strain`)."""
        self.evaluations += 1
        u = self.tr.controls(z)
        effort, grad_u = self.tr.problem.control_cost(u)
        r, Jr = self.strain.residuals(z, jacobian)
        effort += 0.5 * float(r @ r)
        J = self.tr.control_jacobian(z) if jacobian else None
        gradient = None if J is None else J.T @ grad_u + Jr.T @ r
        c = np.array([k.value(z) for k in self.constraints])
        return Point(z, u, effort, gradient, c, J, Jr, r)

    def run(self, z0, *, maxiter: int, tol: float, on_iteration=None, should_stop=None):
        """From ``z0``: the :class:`Outcome` (``on_iteration(Progress, point)`` after each,
        ``should_stop()`` checked before each, True to end the search)."""
        x = self.point(z0)
        lam = np.zeros(len(self.constraints))
        mu, theta, history, efforts = MU_START, THETA_MAX, [], [x.effort]
        reason, it = "maxiter", 0
        for it in range(1, maxiter + 1):
            if should_stop is not None and should_stop():
                reason = "stopped"
                break
            step, lam_new, predicted, sigma = self._step(x, lam, mu, theta)
            mu = self.mu_used
            merit = lambda p: p.effort + sigma * p.violation()  # noqa: E731
            trial = self.point(self.restore(x.z, x.z + step), jacobian=False)
            if self._broken(trial.z):  # a plan the simulation would refuse (torn cloth)
                trial.effort = np.inf
            elif trial.violation() > 0:
                # the trial's own multiplier estimates (the constraints' gradients can vanish
                # at x, on a keyframe's target) keep a miss from being bought with effort
                A_t = self._gradients(trial.z)
                sigma = self._penalty(A_t, x.gradient)
                corrected = self._corrected(x, trial, step, A_t)
                if (corrected is not None and merit(corrected) < merit(trial)
                    and not self._broken(corrected.z)):
                    trial = corrected
            actual = merit(x) - merit(trial)
            ratio = actual / predicted if predicted > 0 else -np.inf
            kept = ratio >= ACCEPT
            if kept:
                x, lam = self.point(trial.z), lam_new
                if ratio > 0.5:
                    mu, theta = max(mu / 2.0, MU_MIN), min(2.0 * theta, THETA_MAX)
            else:
                mu = min((16.0 if ratio < -1.0 else 4.0) * mu + MU_MIN, MU_MAX)
                failed = trial.violation() > 0.5 * (x.violation()
                                                    + np.maximum(self._linear, 0).sum())
                if failed or ratio < -1.0:  # the goal's model failed too, or the merit
                    # rose beyond the model: a step the goal's demand keeps long whatever mu
                    theta = max(theta / 2.0, THETA_MIN)
            report = Progress(it, x.effort, x.violation(),
                              [k.miss(x.z) for k in self.constraints], mu,
                              float(np.linalg.norm(step)), kept, theta, ratio)
            history.append(report)
            if on_iteration is not None:
                on_iteration(report, x)
            if kept:
                efforts.append(x.effort)
            if (kept and np.all(x.c <= self.held) and len(efforts) > SETTLED
                    and np.ptp(efforts[-SETTLED - 1:]) <= tol * max(abs(x.effort), 1e-300)):
                reason = "converged"
                break
            if not kept and mu >= MU_MAX:
                reason = "stalled"
                break
        return Outcome(x.z, reason, it, history), x

    def _step(self, x: Point, lam, mu, theta):
        """``(step, multipliers, predicted merit decrease, sigma)`` of the QP at ``x``, the
        violated constraints asked to fall by the share ``theta``."""
        solve, curvature, mu = self._system(x, lam, mu)
        self.mu_used = mu
        A = self._gradients(x.z)
        # the strain penalty's excess too is asked to fall by the share theta while the
        # goal is not held (a zero-force start stretches the sheet far past the limit),
        # then by its own gradient, whose steps end at the true optimum
        share = 1.0 if np.all(x.c <= self.held) else theta
        p0 = -solve(x.gradient - (1.0 - share) * (x.Jr.T @ x.r))
        W = solve(A)
        # c + a^T p <= c - theta c where violated (a share of it removed), <= 0 elsewhere
        aim = np.where(x.c > 0, theta * x.c, x.c)
        step, lam_a = _active_set(aim, A, p0, W)
        linear = x.c + A.T @ step
        self._solve, self._linear = solve, linear  # for the trial's correction
        self.sigma = max(self.sigma, 2.0 * lam_a.max(initial=0.0))
        sigma = self._penalty(A, x.gradient)
        model = -(x.gradient @ step + 0.5 * step @ curvature(step))
        predicted = model + sigma * (np.maximum(x.c, 0).sum() - np.maximum(linear, 0).sum())
        return step, lam_a, predicted, sigma

    def _system(self, x: Point, lam, mu):
        """``(solve, curvature, mu)``: the step's matrix at ``x`` factored (or, for large
        sheets, solved by conjugate gradients without forming it, :mod:`.linear_solve`), the
        model's matrix (without the damping) times a vector, and the damping used (raised
        while the matrix does not factor)."""
        while True:  # a matrix that does not factor (round-off): more damping
            try:
                if self.linear.iterative(self.tr.size, self.tr.nf):
                    system = iterative_system(self, x, lam, mu, self.linear)
                    self.solves = system.solves
                    return system.solve, system.curvature, mu
                # every operand by rows (a mix converts the large ones at every operation)
                G = x.J.T.tocsr() @ (self.Q @ x.J)  # the one product of the state's size
                curvature = x.Jr.T.tocsr() @ x.Jr
                for l, C in zip(lam, self.C):
                    if l > 0:
                        curvature = curvature + l * C
                solve = self.factor(G + (self._pattern(x) + (curvature + mu * self.metric)))
                return solve, (lambda p: G @ p + curvature @ p), mu
            except ArithmeticError:
                mu = max(4.0 * mu, 1e-8)

    def _pattern(self, x: Point) -> sp.csr_matrix:
        """Every place the step's matrix can ever hold a value, each at a value far below
        round-off (1e-300): added to the matrix it keeps one sparsity pattern across
        iterations, so the factorisation's analysis and its matrix are made once (the strain
        penalty's rows and the products' exact zeros come and go)."""
        if self._fill is None:
            def ones(M):  # every stored entry as 1, its value zero or not
                M = sp.csr_matrix(M, copy=True)
                M.data[:] = 1.0
                return M

            J = ones(x.J)
            P = (J.T @ ones(self.Q) @ J + self.strain.pattern().T @ self.strain.pattern()
                 + ones(self.metric) + sum((ones(C) for C in self.C),
                                           sp.csr_matrix((J.shape[1], J.shape[1]))))
            self._fill = (1e-300 * ones(P)).tocsr()
        return self._fill

    def _broken(self, z) -> bool:
        """Whether the plan ``z`` has a frame the model's own checks refuse (non-finite,
        beyond bounds, a cloth's spring past its blow-up stretch)."""
        x = self.tr.frames(z)
        v = np.diff(x, axis=0) / self.tr.dt
        try:
            for n in range(1, x.shape[0]):
                self.tr.problem.model.check_state(x[n], v[n - 1], n)
        except SimulationError:
            return True
        return False

    def _gradients(self, z) -> np.ndarray:
        return np.stack([k.gradient(z) for k in self.constraints], axis=1)

    def _penalty(self, A, gradient) -> float:
        """The merit's penalty weight, raised to twice the multipliers' least-squares
        estimate ``-a_k^T g / |a_k|^2`` where that is larger (never lowered)."""
        estimate = -(A.T @ gradient) / np.maximum(np.einsum("ik,ik->k", A, A), 1e-300)
        self.sigma = max(self.sigma, 2.0 * estimate.max(initial=0.0))
        return self.sigma

    def _corrected(self, x: Point, trial: Point, step, A_t) -> Point | None:
        """The trial with a second-order correction for the constraints it breaks beyond
        their linearization (the keyframes' misses are quadratic in the positions): the
        least move in the step's metric, on the factor already made, that brings them to
        first order at the trial back to the linear model's value (or to zero); None when
        none needs it."""
        target = np.maximum(self._linear, 0.0)
        broken = np.flatnonzero(trial.c > target)
        if broken.size == 0:
            return None
        W = self._solve(A_t[:, broken])
        S = A_t[:, broken].T @ W
        y = np.linalg.lstsq(S, trial.c[broken] - target[broken], rcond=1e-12)[0]
        return self.point(self.restore(x.z, x.z + step - W @ y), jacobian=False)


def damping_metric(tr, weight: float, share: float = POSITION_SHARE) -> sp.csr_matrix:
    """The damping's metric: the control cost (``weight`` per unit force squared) of the
    inertial forces ``m (p_{n+1} - 2 p_n + p_{n-1}) / dt^2`` a change ``p`` of the positions
    asks, plus ``share`` of the cost of ``m p / dt^2`` itself, ``m`` the free particles'
    mean mass (:func:`inertial_scale`).  The first damps a change that jerks a frame (a snap
    onto a keyframe) hard and one spread smoothly over many frames lightly, where a metric
    of the positions alone prefers the snap (it moves the fewest frames); the second bounds
    the smooth changes too, the directions in which a buckling sheet's forces change the
    least to first order and the linear model fails soonest.  One mass for all: the
    keyframes count every particle alike, and a metric weighing each by its own mass
    squared makes a light one (a sheet's corner holds a quarter to a sixth of an inner
    particle's mass) many times cheaper to move, so the damped step, along ``D^-1`` of the
    keyframes' gradients, throws a sheet's free corners and edges far past their targets in
    the last frames and stretches their springs beyond any model (docs/search_notes.md)."""
    N = tr.N
    T = sp.diags([np.ones(N), -2 * np.ones(N - 1), np.ones(N - 2)], [0, -1, -2],
                 shape=(N, N))  # row: step n; column: frame n+1, n, n-1 (frames 1..N)
    scale = inertial_scale(tr)
    S = sp.kron(T, sp.diags(scale)).tocsr()
    return (weight * (S.T @ S + share * sp.diags(np.tile(scale ** 2, N)))).tocsr()


def inertial_scale(tr) -> np.ndarray:
    """``m / dt^2`` for every free component of a frame, ``m`` the free particles' mean mass:
    the damping metric's weight of a particle (:func:`damping_metric`)."""
    masses = np.repeat(tr.problem.model.masses, 3)[tr.free_flat]
    return np.full(tr.nf, masses.mean() / tr.dt ** 2)


def _active_set(c, A, p0, W):
    """``(step, multipliers)`` of the QP's few constraints ``c + A^T p <= 0`` given the
    unconstrained step ``p0`` and ``W = B^-1 A``: a primal active set (a constraint is
    added while its linearization is violated, dropped while its multiplier is negative)."""
    m = c.size
    active = [k for k in range(m) if c[k] + A[:, k] @ p0 > 0]
    lam = np.zeros(m)
    for _ in range(4 * m + 4):
        lam[:] = 0.0
        if active:
            S = A[:, active].T @ W[:, active]
            rhs = c[active] + A[:, active].T @ p0
            lam[active] = np.linalg.lstsq(S, rhs, rcond=1e-12)[0]
        step = p0 - W @ lam
        negative = [k for k in active if lam[k] < 0]
        if negative:
            active.remove(min(negative, key=lambda k: lam[k]))
            continue
        violated = [k for k in range(m) if k not in active and c[k] + A[:, k] @ step > 0]
        if not violated:
            break
        active.append(max(violated, key=lambda k: c[k] + A[:, k] @ step))
    return step, lam
