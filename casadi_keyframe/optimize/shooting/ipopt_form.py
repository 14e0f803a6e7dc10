"""Multiple shooting as a constrained problem for IPOPT (CasADi's ``nlpsol``): the
objective on the stitched segments, the scaled defects as equality constraints.

IPOPT needs the constraints' Jacobian as a matrix: each defect row is one backward sweep
over its segment (:meth:`~.form.Shooting.defect_jacobian`, reusing the forward pass's
factorisations, in the workers that ran it), so a Jacobian costs ``2 x free components``
sweeps per segment, and the Lagrangian's Hessian is IPOPT's limited-memory one.  The
objective, its gradient, the defects and their Jacobian are Callbacks over one memoised
evaluation per point; every Callback is kept referenced on the solver (one collected early
makes IPOPT fail silently).
"""
from __future__ import annotations

import signal

import casadi as ca
import numpy as np

from ...interrupts import Interrupted, catching
from ..ipopt import IterationHook, ipopt_options
from ..outcome import ipopt_outcome


class _Point:
    """The evaluation (objective, gradient, defects) and the Jacobian at the last z asked
    for, through the shooting evaluator (memoised there)."""

    def __init__(self, shooting, runner, ev):
        self.shooting, self.runner, self.ev = shooting, runner, ev
        self.jz, self.jac = None, None

    def at(self, z):
        self.f, self.g = self.ev(z)
        self.info = self.ev.last_info
        return self

    def jacobian(self, z):
        z = np.asarray(z, dtype=float).ravel()
        if self.jz is None or not np.array_equal(z, self.jz):
            self.ev(z, force=not np.array_equal(z, self.ev.swept))  # the records at z
            self.jac = self.shooting.defect_jacobian(self.runner).tocsc()
            self.jz = z
        return self.jac


class _Fn(ca.Callback):
    """A Callback of z with a Jacobian Callback (``which``: "f" or "g")."""

    def __init__(self, point, which, n, m, pattern):
        ca.Callback.__init__(self)
        self.point, self.which, self.n, self.m, self.pattern = point, which, n, m, pattern
        self.construct(which, {"enable_fd": False})

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1 if self.which == "f" else self.m, 1)

    def eval(self, arg):
        p = self.point.at(arg[0])
        if self.which == "f":
            return [p.f]
        return [self.point.shooting.defect_vector(p.info["defects"]) if p.info is not None
                else np.full(self.m, 1e10)]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _Jac(self.point, self.which, self.n, self.m, self.pattern, name)
        return self._jac


class _Jac(ca.Callback):
    def __init__(self, point, which, n, m, pattern, name):
        ca.Callback.__init__(self)
        self.point, self.which, self.n, self.m, self.pattern = point, which, n, m, pattern
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 2

    def get_sparsity_in(self, i):
        if i == 0:
            return ca.Sparsity.dense(self.n, 1)
        return ca.Sparsity.dense(1 if self.which == "f" else self.m, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, self.n) if self.which == "f" else self.pattern

    def eval(self, arg):
        if self.which == "f":
            return [self.point.at(arg[0]).g.reshape(1, -1)]
        jac = self.point.jacobian(arg[0])
        return [ca.DM(self.pattern, _on_pattern(jac, self.pattern))]


def _on_pattern(jac, pattern) -> np.ndarray:
    """The entries of the sparse ``jac`` at CasADi ``pattern``'s nonzeros (column major)."""
    rows, cols = pattern.get_triplet()
    return np.asarray(jac[rows, cols]).ravel()


def jacobian_pattern(shooting, jac) -> ca.Sparsity:
    """The defects' Jacobian pattern: where a structurally nonzero block may be (each
    segment's forces and start, the next node), read from one Jacobian's block layout."""
    dense_rows = []
    for k in range(shooting.K - 1):
        rows = slice(2 * shooting.nf * k, 2 * shooting.nf * (k + 1))
        block = jac[rows]
        cols = np.flatnonzero(np.asarray(abs(block).sum(axis=0)).ravel() > 0)
        dense_rows.append((rows, cols))
    r, c = [], []
    for rows, cols in dense_rows:
        for i in range(rows.start, rows.stop):
            r.extend([i] * cols.size)
            c.extend(cols.tolist())
    return ca.Sparsity.triplet(jac.shape[0], jac.shape[1], r, c)


def run_nlp(shooting, runner, ev, z0, maxiter, tol, options, on_iteration, deadline):
    """IPOPT on the constrained form from ``z0``; ``on_iteration(z)`` after each
    iteration.  Returns ``(status, message, z)`` with IPOPT's last point; an interrupt
    raises, the goal met raises :class:`~.goal.GoalReached`."""
    point = _Point(shooting, runner, ev)
    point.at(z0)
    pattern = jacobian_pattern(shooting, point.jacobian(z0))
    n, m = shooting.size, 2 * shooting.nf * (shooting.K - 1)
    f, g = _Fn(point, "f", n, m, pattern), _Fn(point, "g", n, m, pattern)
    it = IterationHook(n, on_iteration, m=m, with_point=True)
    Z = ca.MX.sym("z", n)
    ipopt = ipopt_options(maxiter, tol, options, deadline)
    solver = ca.nlpsol("shooting", "ipopt", {"x": Z, "f": f(Z), "g": g(Z)},
                       {"ipopt": ipopt, "print_time": False, "iteration_callback": it,
                        "error_on_fail": False})
    solver._keep = (f, g, it)
    lb, ub = shooting.bounds()
    with catching(signal.SIGINT) as caught:
        out = solver(x0=z0, lbx=lb, ubx=ub, lbg=0, ubg=0)
    signum = caught.signum or it.interrupted
    if signum:
        raise Interrupted(signum)
    if it.reached is not None:
        raise it.reached
    status, message = ipopt_outcome(solver.stats().get("return_status", "unknown"),
                                    maxiter=maxiter)
    return status, message, np.asarray(out["x"]).ravel()
