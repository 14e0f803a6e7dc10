r"""Least effort under the goal where the controls are fewer than a force per free particle,
by IPOPT: the unknowns are the positions and the controls ``w = (z, u)``, every step an
equality constraint (:mod:`.defects`), beside the keyframes (:mod:`.goal`) and the physical
stretch limit (:mod:`.stretch`) as in :mod:`.interior`.  The effort is the problem's control
cost in ``u`` (its Hessian ``Q`` constant) and its strain penalty in ``z`` (:mod:`.strain`,
on its Gauss-Newton matrix); the Hessian of the Lagrangian adds the defects' exact curvature
weighed by their multipliers (``hessian="gauss-newton"``), or IPOPT builds a limited-memory
one (``"limited-memory"``).  The controls' bounds are IPOPT's bounds on ``u``.

The result is the controls ``u``: the evaluator judges every iterate by the problem's own run
of its controls, and the message says how far the last one's run is from its positions.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...state import SimulationError
from ..finish.constraint import control_hessian
from ..outcome import ipopt_outcome
from .defects import StepDefects
from .goal import goal_constraints
from .interior import PositionNLP, each_iterate, ones_pattern, search
from .strain import StrainPenalty
from .stretch import StretchLimit
from .transcription import TranscriptionError

DEFECT_TOLERANCE = 1e-9  # m: IPOPT's constr_viol_tol on the steps' defects
METIS = 5  # MUMPS's ordering (its automatic choice is far slower on these systems)
MU_INIT = 1e-6  # IPOPT's first barrier parameter: the effort is small beside its default


def _pad(M, width) -> sp.csr_matrix:
    """``M`` (columns: the positions) with zero columns for the controls up to ``width``."""
    M = sp.csr_matrix(M)
    return sp.hstack([M, sp.csr_matrix((M.shape[0], width - M.shape[1]))]).tocsr()


def _square(M, width) -> sp.csr_matrix:
    """A square ``M`` in the top-left corner of a ``width`` square."""
    return sp.block_diag([M, sp.csr_matrix((width - M.shape[0],) * 2)]).tocsr()


class DefectNLP(PositionNLP):
    """The problem of the module docstring on the defects ``d`` (a
    :class:`~.defects.StepDefects`): ``goals`` the keyframes' constraints, ``Q`` the control
    terms' Hessian, ``stretch`` a :class:`~.stretch.StretchLimit` or None."""

    def __init__(self, d: StepDefects, goals, Q, stretch: StretchLimit | None,
                 limited_memory: bool = False):
        self.tr = self.d = d
        self.goals, self.Q, self.stretch = goals, sp.csr_matrix(Q), stretch
        self.strain = StrainPenalty(d)
        self.limited_memory = limited_memory
        self.C = [_square(g.hessian(), d.width) for g in goals]
        self.inequalities = len(goals) + (0 if stretch is None else stretch.size)
        self.m = self.inequalities + d.rows
        self._key, self._point = None, None
        self._jacobian_fill = self._hessian_fill = None

    @property
    def size(self) -> int:
        return self.d.width

    def point(self, w) -> dict:
        key = w.tobytes()
        if key != self._key:
            z, u = self.d.split(w)
            effort, grad_u = self.d.problem.control_cost(u)
            r, Jr = self.strain.residuals(z)
            self._point = {"effort": effort + 0.5 * float(r @ r),
                           "gradient": np.concatenate([Jr.T @ r, grad_u]), "Jr": Jr}
            self._key = key
        return self._point

    # -- the constraints: keyframes, stretch (below their bounds), defects (zero) ----------
    def values(self, w) -> np.ndarray:
        z, _ = self.d.split(w)
        stretch = [] if self.stretch is None else [self.stretch.values(z)]
        return np.concatenate([[g.value(z) + g.bound for g in self.goals], *stretch,
                               self.d.values(w)])

    def lower(self) -> np.ndarray:
        return np.concatenate([np.full(self.inequalities, -np.inf), np.zeros(self.d.rows)])

    def upper(self) -> np.ndarray:
        stretch = [] if self.stretch is None else [np.full(self.stretch.size,
                                                           self.stretch.bound)]
        return np.concatenate([[g.bound for g in self.goals], *stretch,
                               np.zeros(self.d.rows)])

    def variable_bounds(self) -> dict:
        """The controls' bounds (the positions' are free)."""
        lower, upper = self.d.problem.bounds()
        free = np.full(self.d.size, np.inf)
        return {"lbx": np.concatenate([-free, lower]), "ubx": np.concatenate([free, upper])}

    def ipopt_options(self, w0) -> dict:
        options = {"constr_viol_tol": DEFECT_TOLERANCE, "mumps_pivot_order": METIS,
                   "mu_init": MU_INIT}
        if self.limited_memory:
            options["hessian_approximation"] = "limited-memory"
        return options

    def jacobian(self, w) -> sp.csc_matrix:
        z, _ = self.d.split(w)
        width = self.d.width
        goals = _pad(np.stack([g.gradient(z) for g in self.goals]), width)
        stretch = [] if self.stretch is None else [_pad(self.stretch.jacobian(z), width)]
        return self._on(sp.vstack([goals, *stretch, self.d.jacobian(w)]), "_jacobian_fill",
                        self._jacobian_pattern)

    def _jacobian_pattern(self):
        width = self.d.width
        goals = _pad(sp.vstack([sp.csr_matrix((abs(g.R).sum(axis=0).A1 > 0).astype(float))
                                for g in self.goals]), width)
        stretch = [] if self.stretch is None else [
            _pad(ones_pattern(self.stretch.jacobian(np.ones(self.d.size))), width)]
        return sp.vstack([goals, *stretch, self.d.jacobian_pattern()])

    # -- the Hessian of the Lagrangian -------------------------------------------------------
    def hessian(self, w, sigma: float, lam) -> sp.csc_matrix:
        """Its upper triangle (module docstring), on the fixed pattern."""
        p = self.point(w)
        width, count = self.d.width, len(self.goals)
        H = sigma * sp.block_diag([p["Jr"].T @ p["Jr"], self.Q]).tocsr()
        for l, C in zip(lam, self.C):
            H = H + l * C
        if self.stretch is not None:
            H = H + _square(self.stretch.hessian(lam[count:self.inequalities]), width)
        H = H + self.d.curvature(w, lam[self.inequalities:])
        return self._on(sp.triu(H), "_hessian_fill", self._hessian_pattern)

    def _hessian_pattern(self):
        width = self.d.width
        S = self.strain.pattern()
        H = sp.block_diag([S.T @ S, ones_pattern(self.Q)]).tocsr() + sum(ones_pattern(C) for C in self.C)
        if self.stretch is not None:
            H = H + _square(ones_pattern(self.stretch.hessian(np.ones(self.stretch.size))), width)
        return sp.triu(ones_pattern(H + self.d.curvature_pattern()))

    def start(self) -> np.ndarray:
        """A point at which the patterns are read (any point gives them)."""
        return np.concatenate([self.d.unknowns(self.d.base), np.zeros(self.d.nu)])


def run_defects(problem, ev, u0, call, start_positions):
    """The search of the module docstring (``method="transcription"`` on fewer controls);
    ``(status, message)``."""
    options = call.options
    if options.hessian == "exact":
        raise TranscriptionError(
            f"{problem.name}: hessian=exact adds the effort's second derivatives; with fewer "
            "controls than a force per particle the effort's only curved part is the strain "
            "penalty, and the steps' curvature is exact already: use hessian=gauss-newton "
            "(the default) or hessian=limited-memory")
    d = StepDefects(problem)
    stretch = None
    if problem.limits is not None and getattr(problem.model, "springs", None) is not None:
        stretch = StretchLimit(d, problem.limits.stretch)
    nlp = DefectNLP(d, goal_constraints(d, options.margin), control_hessian(problem), stretch,
                    limited_memory=options.hessian == "limited-memory")
    given = u0 is not None and not np.array_equal(np.asarray(u0), problem.initial_controls())
    start = "controls" if given else options.start
    u_start = problem.initial_controls() if u0 is None else np.asarray(u0, float)
    w0 = np.concatenate([d.unknowns(start_positions(problem, start, u_start)), u_start])

    each = each_iterate(lambda w: ev.offer(d.split(w)[1]), call)
    status, w, iterations = search(nlp, w0, maxiter=call.maxiter, tol=options.settle,
                                   deadline=call.deadline, on_iteration=each)
    z, u = d.split(w)
    said = (f"{iterations} IPOPT iterations on the positions and the {u.size} controls, "
            f"every step a constraint; " + replay_gap(problem, d, z, u, ev))
    result, message = ipopt_outcome(status, maxiter=call.maxiter)
    return result, f"{message} ({said})"


def replay_gap(problem, d, z, u, ev) -> str:
    """How far the run of the controls ``u`` is from the positions ``z`` (offered to ``ev``)."""
    try:
        ev.offer(u)
        x = problem.simulate(u, records=False).x
    except SimulationError as err:
        return f"the simulation refuses its last controls ({err})"
    off = np.linalg.norm(x - d.frames(z), axis=2).max(axis=1)
    frame = int(np.argmax(off))
    said = (f"their run is within {1e3 * off[frame]:.1e} mm of the positions (frame "
            f"{frame})")
    if off[frame] > 1e-4:
        said += "; the result is the controls, judged by their own run"
    return said
