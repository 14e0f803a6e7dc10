"""IPOPT (CasADi's ``nlpsol``) as a search method, fed by the evaluator through Callbacks.

The objective is a ``casadi.Callback`` whose Jacobian is another Callback returning the
chosen gradient route's gradient; IPOPT runs with a limited-memory Hessian.  Every Callback
is kept referenced on the solver (one collected early makes IPOPT fail silently with
``Invalid_Number_Detected``), and ``stats()['return_status']`` says how it ended.

``options`` go to IPOPT over this module's defaults (limited-memory Hessian with 20 pairs,
``max_iter``, ``tol``, silent).  Their names are IPOPT's own: IPOPT decides whether it
knows a name (:func:`check_options` asks it before the search starts) and its option
documentation gives the names to suggest (:func:`option_names`).
"""
from __future__ import annotations

import contextlib
import functools
import io
import re
import signal
import time

import casadi as ca
import numpy as np

from ..interrupts import Interrupted, catching
from .goal import GoalReached
from .outcome import ipopt_outcome


def _made_with(ipopt_options: dict) -> tuple[str | None, str]:
    """Make an IPOPT solver of a one-variable problem with these options (IPOPT reads and
    checks its options then): ``(CasADi's error or None, what IPOPT printed)``."""
    x = ca.MX.sym("x")
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):  # CasADi prints through sys.stdout
            ca.nlpsol("options", "ipopt", {"x": x, "f": x ** 2},
                      {"ipopt": ipopt_options, "print_time": False})
    except RuntimeError as err:
        return str(err), printed.getvalue()
    return None, printed.getvalue()


@functools.cache
def option_names() -> tuple[str, ...]:
    """The option names IPOPT documents, advanced ones included, in its documentation's
    order: read from IPOPT's ``print_options_documentation`` at first use.  (IPOPT also
    knows a few it does not document, such as ``sb``.)"""
    error, text = _made_with({"print_options_documentation": "yes",
                              "print_advanced_options": "yes", "print_level": 5})
    names = tuple(dict.fromkeys(re.findall(r"^([a-z][a-z0-9_]*)[ (]", text, re.M)))
    if error or not names:
        raise RuntimeError("IPOPT printed no option documentation through CasADi, so its "
                           f"option names cannot be listed here ({error or 'no text'})")
    return names


_TYPES = {"is_int()": "a whole number", "is_double()": "a number",
          "is_string()": "a string"}


def check_options(options: dict) -> list[str]:
    """IPOPT's own verdict on ``options``, asked one option at a time before the search:
    returns the names IPOPT does not know; a value of the wrong type, or one IPOPT does not
    allow, raises ValueError naming the option, with IPOPT's explanation."""
    unknown = []
    for key, value in options.items():
        error, printed = _made_with({"print_level": 0, key: value})
        if error is None:
            continue
        if "No such IPOPT option" in error:
            unknown.append(key)
            continue
        kind = next((t for a, t in _TYPES.items() if a in error), None)
        if kind:
            raise ValueError(f"IPOPT option {key!r} must be {kind}, got {value!r}")
        said = printed.strip() or error.strip().splitlines()[-1]
        raise ValueError(f"IPOPT refuses option {key!r} = {value!r}:\n{said}")
    return unknown


class _Objective(ca.Callback):
    """phi(u) for IPOPT, with the gradient from the chosen strategy as its Jacobian."""

    def __init__(self, ev, n):
        ca.Callback.__init__(self)
        self.ev, self.n = ev, n
        self.construct("phi", {"enable_fd": False})

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        return [self.ev(np.asarray(arg[0]).ravel())[0]]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _Gradient(self.ev, self.n, name, opts)  # IPOPT needs it kept alive
        return self._jac


class _Gradient(ca.Callback):
    def __init__(self, ev, n, name, opts):
        ca.Callback.__init__(self)
        self.ev, self.n = ev, n
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 2

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, self.n)

    def eval(self, arg):
        return [self.ev(np.asarray(arg[0]).ravel())[1].reshape(1, -1)]


class IterationHook(ca.Callback):
    """IPOPT's per-iteration hook for ``n`` unknowns and ``m`` constraints: calls
    ``on_iteration()`` (``on_iteration(x)`` with ``with_point``) after each iteration and
    returns 1, which stops IPOPT, on Ctrl-C or when the goal is met."""

    def __init__(self, n, on_iteration, *, m: int = 0, with_point: bool = False):
        ca.Callback.__init__(self)
        self.n, self.m, self.on_iteration, self.with_point = n, m, on_iteration, with_point
        self.count, self.interrupted = 0, None
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
                if self.with_point:
                    self.on_iteration(np.asarray(arg[0]).ravel())
                else:
                    self.on_iteration()
        except KeyboardInterrupt as err:
            self.interrupted = getattr(err, "signum", signal.SIGINT)
            return [1]
        except GoalReached as reached:  # IPOPT stops on 1; the search hears of it below
            self.reached = reached
            return [1]
        return [0]


def ipopt_options(maxiter, tol, options, deadline) -> dict:
    """IPOPT's options for a search: limited-memory Hessian, silent, ``deadline`` (a
    ``perf_counter`` time or None) as ``max_wall_time``, the user's ``options`` last."""
    ipopt = {"hessian_approximation": "limited-memory", "max_iter": maxiter, "tol": tol,
             "print_level": 0, "sb": "yes", "limited_memory_max_history": 20}
    if deadline is not None:
        ipopt["max_wall_time"] = max(deadline - time.perf_counter(), 1e-3)
    ipopt.update(options)
    return ipopt


def run(problem, ev, u0, maxiter, tol, options, on_iteration, deadline):
    """Search from ``u0`` with the evaluator ``ev`` (f and gradient asked for separately,
    memoised), calling ``on_iteration()`` after each iteration; ``deadline`` becomes IPOPT's
    ``max_wall_time``.  Returns ``(status, message)`` (:mod:`.outcome`); an interrupt raises
    :class:`~casadi_keyframe.interrupts.Interrupted`."""
    n = problem.size
    phi = _Objective(ev, n)
    it = IterationHook(n, on_iteration)
    U = ca.MX.sym("u", n)
    ipopt = ipopt_options(maxiter, tol, options, deadline)
    solver = ca.nlpsol("keyframe", "ipopt", {"x": U, "f": phi(U)},
                       {"ipopt": ipopt, "print_time": False, "iteration_callback": it,
                        "error_on_fail": False})
    solver._keep = (phi, it)  # Callbacks must outlive the solver
    lb, ub = problem.bounds()
    # an interrupt CasADi catches inside IPOPT ends it as NonIpopt_Exception_Thrown: the
    # handler's log, the evaluator and the iteration hook say it was one
    with catching(signal.SIGINT) as caught:
        solver(x0=u0, lbx=lb, ubx=ub)
    signum = caught.signum or ev.interrupted or it.interrupted
    if signum:
        raise Interrupted(signum)
    if it.reached is not None:
        raise it.reached
    return ipopt_outcome(solver.stats().get("return_status", "unknown"),
                         maxiter=ipopt["max_iter"])
