r"""Least effort under the goal, in positions, by IPOPT (CasADi's ``nlpsol``): the
transcription's effort (control cost and strain penalty, as :mod:`.sqp` minimises) subject to
every keyframe within its tolerance (:mod:`.goal`) and every spring within the physical
stretch limit at every frame (:mod:`.stretch`), which an interior point holds by the
thousand where the SQP's active set holds a few.

IPOPT is fed numbers, not expressions: the effort, the constraints and their sparse Jacobians
come from the transcription's own routines through Callbacks, and the Hessian of the
Lagrangian is

    sigma (J^T Q J + Jr^T Jr) + sum_k lambda_k C_k,

the effort's Gauss-Newton matrix (as the SQP's) and the constraints' exact constant
Hessians.  The exact Hessian of the effort adds the forces' second derivatives weighed by
the control cost's gradient; where the sheet buckles they make it indefinite, and IPOPT's
inertia correction then damps every step (docs/search_notes.md measures both).  The
matrix's sparsity is fixed once (every entry it can ever hold), so IPOPT analyses it once.
"""
from __future__ import annotations

import signal

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...interrupts import Interrupted, OutOfTime, catching, check
from ...state import SimulationError
from ..ipopt_callbacks import IterationHook, NumericFunction
from .curvature import EffortCurvature
from .strain import StrainPenalty
from .stretch import StretchLimit


def _sparsity(M) -> ca.Sparsity:
    M = sp.csc_matrix(M)
    M.sort_indices()
    return ca.Sparsity(M.shape[0], M.shape[1], M.indptr.tolist(), M.indices.tolist())


def ones_pattern(M) -> sp.csr_matrix:
    """Every stored entry of ``M`` as 1 (its pattern)."""
    M = sp.csr_matrix(M, copy=True)
    M.data[:] = 1.0
    return M


class PositionNLP:
    """The problem of the module docstring on a transcription ``tr``: ``goals`` the
    keyframes' constraints, ``Q`` the control terms' Hessian, ``stretch`` a
    :class:`~.stretch.StretchLimit`; ``exact``: the effort's exact Hessian
    (:mod:`.curvature`) in place of its Gauss-Newton matrix."""

    def __init__(self, tr, goals, Q, stretch: StretchLimit, exact: bool = False):
        self.tr, self.goals, self.Q, self.stretch = tr, goals, sp.csr_matrix(Q), stretch
        self.strain = StrainPenalty(tr)
        self.curvature = EffortCurvature(tr, self.strain) if exact else None
        self.C = [g.hessian() for g in goals]
        self.m = len(goals) + stretch.size
        self._key, self._point = None, None
        self._jacobian_fill = self._hessian_fill = None

    limited_memory = False  # True: IPOPT builds the Hessian (no hess_lag)

    @property
    def size(self) -> int:
        """The number of unknowns."""
        return self.tr.size

    def lower(self):
        """The bounds the values are held above."""
        return -np.inf

    def variable_bounds(self) -> dict:
        """IPOPT's ``lbx``, ``ubx`` (none: the positions are free)."""
        return {}

    def ipopt_options(self, z0) -> dict:
        """IPOPT's options of this problem: the effort scaled to 1 at the start."""
        return {"obj_scaling_factor": 1.0 / max(abs(self.point(np.asarray(z0, float))["effort"]),
                                                1e-12)}

    # -- the effort ---------------------------------------------------------------------
    def point(self, z) -> dict:
        """Effort, its gradient and the Jacobians at ``z`` (the last one kept: IPOPT asks
        for value, gradient and Hessian at the same point)."""
        key = z.tobytes()
        if key != self._key:
            u = self.tr.controls(z)
            effort, grad_u = self.tr.problem.control_cost(u)
            r, Jr = self.strain.residuals(z)
            J = self.tr.control_jacobian(z)
            self._point = {"effort": effort + 0.5 * float(r @ r),
                           "gradient": J.T @ grad_u + Jr.T @ r, "J": J, "Jr": Jr,
                           "grad_u": grad_u}
            self._key = key
        return self._point

    # -- the constraints ----------------------------------------------------------------
    def values(self, z) -> np.ndarray:
        return np.concatenate([[g.value(z) + g.bound for g in self.goals],
                               self.stretch.values(z)])

    def upper(self) -> np.ndarray:
        """The bounds the values are held below."""
        return np.concatenate([[g.bound for g in self.goals],
                               np.full(self.stretch.size, self.stretch.bound)])

    def jacobian(self, z) -> sp.csc_matrix:
        goals = sp.csr_matrix(np.stack([g.gradient(z) for g in self.goals]))
        return self._on(sp.vstack([goals, self.stretch.jacobian(z)]), "_jacobian_fill",
                        self._jacobian_pattern)

    def _jacobian_pattern(self):
        goals = sp.vstack([sp.csr_matrix((abs(g.R).sum(axis=0).A1 > 0).astype(float))
                           for g in self.goals])
        stretch = ones_pattern(self.stretch.jacobian(np.ones(self.tr.size)))
        return sp.vstack([goals, stretch])

    # -- the Hessian of the Lagrangian ----------------------------------------------------
    def hessian(self, z, sigma: float, lam) -> sp.csc_matrix:
        """Its upper triangle (module docstring), on the fixed pattern."""
        p = self.point(z)
        H = sigma * (p["J"].T @ (self.Q @ p["J"]) + p["Jr"].T @ p["Jr"])
        if self.curvature is not None:
            H = H + sigma * self.curvature(z, p["grad_u"])
        for l, C in zip(lam, self.C):
            H = H + l * C
        H = H + self.stretch.hessian(lam[len(self.goals):])
        return self._on(sp.triu(H), "_hessian_fill", self._hessian_pattern)

    def _hessian_pattern(self):
        J = ones_pattern(self.tr.control_jacobian(self.tr.unknowns(self.tr.base)))
        S = self.strain.pattern()
        H = (J.T @ ones_pattern(self.Q) @ J + S.T @ S + sum(ones_pattern(C) for C in self.C)
             + ones_pattern(self.stretch.hessian(np.ones(self.stretch.size))))
        return sp.triu(ones_pattern(H))

    def _on(self, M, name, pattern):
        """``M`` on its fixed pattern (made once by ``pattern()``): csc, every place of the
        pattern stored (a value far below round-off fills the places ``M`` leaves out)."""
        if getattr(self, name) is None:
            setattr(self, name, (1e-300 * ones_pattern(pattern())).tocsc())
        fill = getattr(self, name)
        out = (M + fill).tocsc()
        out.sort_indices()
        if out.nnz != fill.nnz:
            raise RuntimeError(f"an entry outside the fixed pattern ({out.nnz} stored, the "
                               f"pattern {fill.nnz}): the pattern misses a term")
        return out

    def start(self) -> np.ndarray:
        """A point at which the patterns are read (the passive motion: any point gives them)."""
        return self.tr.unknowns(self.tr.base)

    def patterns(self) -> tuple[ca.Sparsity, ca.Sparsity]:
        """The Jacobian's and the Hessian's CasADi sparsity."""
        z = self.start()
        return (_sparsity(self.jacobian(z)),
                _sparsity(self.hessian(z, 1.0, np.ones(self.m))))


class _Numeric(ca.Callback):
    """A function of IPOPT's ``(x, p, ...)`` computed in numpy: ``ins`` and ``outs`` its
    CasADi sparsities, ``fn(*arrays)`` returns each output's nonzeros (the derivatives
    IPOPT asks for: ``grad_f``, ``jac_g``, ``hess_lag``)."""

    def __init__(self, name, ins, outs, fn):
        ca.Callback.__init__(self)
        self.ins, self.outs, self.fn = ins, outs, fn
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return len(self.ins)

    def get_n_out(self):
        return len(self.outs)

    def get_sparsity_in(self, i):
        return self.ins[i]

    def get_sparsity_out(self, i):
        return self.outs[i]

    def eval(self, arg):
        values = self.fn(*(np.asarray(a).ravel() for a in arg))
        return [ca.DM(s, np.asarray(v, float).ravel()) for s, v in zip(self.outs, values)]


def _derivatives(nlp: PositionNLP) -> dict:
    """IPOPT's ``grad_f``, ``jac_g`` and ``hess_lag`` for ``nlp`` (nlpsol's options; no
    ``hess_lag`` where IPOPT builds a limited-memory one)."""
    n, m = nlp.size, nlp.m
    x, p, one = ca.Sparsity.dense(n, 1), ca.Sparsity(0, 0), ca.Sparsity.dense(1, 1)
    jac_pattern, hess_pattern = (_sparsity(nlp.jacobian(nlp.start())), None) \
        if nlp.limited_memory else nlp.patterns()
    derivatives = {
        "grad_f": _Numeric("grad_f", [x, p], [one, x],
                           lambda z, _: (nlp.point(z)["effort"], nlp.point(z)["gradient"])),
        "jac_g": _Numeric("jac_g", [x, p], [ca.Sparsity.dense(m, 1), jac_pattern],
                          lambda z, _: (nlp.values(z), nlp.jacobian(z).data))}
    if hess_pattern is not None:
        derivatives["hess_lag"] = _Numeric(
            "hess_lag", [x, p, one, ca.Sparsity.dense(m, 1)], [hess_pattern],
            lambda z, _, sigma, lam: (nlp.hessian(z, sigma[0], lam).data,))
    return derivatives


def each_iterate(offer, call):
    """IPOPT's per-iteration callback for a call: ``offer(w)`` the iterate to the run's
    keeper (an interior iterate the simulation refuses, a torn cloth, is skipped), then a
    safe point for signals, the deadline and the call's progress."""
    def each(w):
        try:
            offer(w)
        except SimulationError:
            pass
        check()
        if call.deadline.passed():
            raise OutOfTime(call.deadline)
        call.on_iteration()

    return each


def search(nlp: PositionNLP, z0, *, maxiter: int, tol: float, deadline, on_iteration):
    """IPOPT from ``z0`` on ``nlp``; ``on_iteration(z)`` after each iteration.  Returns
    ``(IPOPT's return status, its last z, iterations)``; an interrupt raises
    :class:`~casadi_keyframe.interrupts.Interrupted`, the deadline
    :class:`~casadi_keyframe.interrupts.OutOfTime`."""
    n = nlp.size
    derivatives = _derivatives(nlp)
    jac_pattern = derivatives["jac_g"].sparsity_out(1)
    f = NumericFunction("effort", n, ca.Sparsity.dense(1, 1),
                        lambda z: nlp.point(z)["effort"], ca.Sparsity.dense(1, n),
                        lambda z: nlp.point(z)["gradient"].reshape(1, -1))
    g = NumericFunction("goal", n, ca.Sparsity.dense(nlp.m, 1), nlp.values, jac_pattern,
                        lambda z: ca.DM(jac_pattern, nlp.jacobian(z).data))
    hook = IterationHook(n, on_iteration, m=nlp.m)
    options = {"max_iter": maxiter, "tol": tol, "print_level": 0, "sb": "yes",
               **nlp.ipopt_options(z0)}
    if deadline.limit is not None:
        options["max_wall_time"] = max(deadline.left(), 1e-3)
    X = ca.MX.sym("z", n)
    solver = ca.nlpsol("positions", "ipopt", {"x": X, "f": f(X), "g": g(X)},
                       {"ipopt": options, **derivatives, "print_time": False,
                        "iteration_callback": hook, "error_on_fail": False})
    solver._keep = (f, g, *derivatives.values(), hook)  # Callbacks must outlive the solver
    with catching(signal.SIGINT) as caught:
        out = solver(x0=z0, lbg=nlp.lower(), ubg=nlp.upper(), **nlp.variable_bounds())
    signum = caught.signum or hook.interrupted
    if signum:
        raise Interrupted(signum)
    if hook.timed_out:
        raise OutOfTime(deadline)
    if hook.reached is not None:
        raise hook.reached
    stats = solver.stats()
    return (stats.get("return_status", "unknown"), np.asarray(out["x"]).ravel(),
            int(stats.get("iter_count", hook.count)))
