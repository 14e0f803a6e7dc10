"""The Callbacks that feed IPOPT (CasADi's ``nlpsol``) numbers computed in numpy: a function
of the unknowns with its Jacobian (:class:`NumericFunction`) and the per-iteration hook that
reports each iterate and stops IPOPT on a signal, the deadline or the goal met
(:class:`IterationHook`).  Shared by the search in the controls (:mod:`.methods.ipopt`) and
the search in positions (:mod:`.positions.interior`).  Every Callback must stay referenced
while its solver lives (one collected early makes IPOPT fail silently)."""
from __future__ import annotations

import signal

import casadi as ca
import numpy as np

from ..interrupts import OutOfTime
from .goal import GoalReached


class NumericFunction(ca.Callback):
    """A function of the ``n`` unknowns for IPOPT: ``value(x)`` shaped ``out``, with the
    Callback :class:`_Jacobian` of ``jacobian(x)`` on the sparsity ``pattern``.  The
    objective is one (its gradient from the chosen route), the equality constraints
    another (:func:`search`)."""

    def __init__(self, name, n, out, value, pattern, jacobian):
        ca.Callback.__init__(self)
        self.n, self.out, self.value = n, out, value
        self.pattern, self.jacobian = pattern, jacobian
        self.construct(name, {"enable_fd": False})

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1)

    def get_sparsity_out(self, i):
        return self.out

    def eval(self, arg):
        return [self.value(np.asarray(arg[0]).ravel())]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _Jacobian(name, self.n, self.out, self.pattern, self.jacobian)
        return self._jac  # IPOPT needs it kept alive


class _Jacobian(ca.Callback):
    def __init__(self, name, n, out, pattern, jacobian):
        ca.Callback.__init__(self)
        self.n, self.out, self.pattern, self.jacobian = n, out, pattern, jacobian
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 2

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1) if i == 0 else self.out

    def get_sparsity_out(self, i):
        return self.pattern

    def eval(self, arg):
        return [self.jacobian(np.asarray(arg[0]).ravel())]


class IterationHook(ca.Callback):
    """IPOPT's per-iteration hook for ``n`` unknowns and ``m`` constraints: calls
    ``on_iteration(x)`` with the iterate after each iteration and returns 1, which stops
    IPOPT, on Ctrl-C or when the goal is met."""

    def __init__(self, n, on_iteration, *, m: int = 0):
        ca.Callback.__init__(self)
        self.n, self.m, self.on_iteration = n, m, on_iteration
        self.count, self.interrupted, self.timed_out = 0, None, False
        self.reached = None  # the GoalReached that stopped it
        self.construct("iteration", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_sparsity_in(self, i):
        size = {"x": self.n, "lam_x": self.n, "f": 1, "g": self.m, "lam_g": self.m,
                "lam_p": 0}[ca.nlpsol_out(i)]
        return ca.Sparsity.dense(size, 1) if size else ca.Sparsity(0, 0)

    def eval(self, arg):
        try:
            self.count += 1
            if self.count > 1:  # IPOPT reports iteration 0, the start, first
                self.on_iteration(np.asarray(arg[0]).ravel())
        except KeyboardInterrupt as err:
            self.interrupted = getattr(err, "signum", signal.SIGINT)
            return [1]
        except OutOfTime:
            self.timed_out = True
            return [1]
        except GoalReached as reached:  # IPOPT stops on 1; the search hears of it below
            self.reached = reached
            return [1]
        return [0]
