"""IPOPT (CasADi's ``nlpsol``) as a search method, fed by the evaluator through Callbacks.

The objective is a ``casadi.Callback`` whose Jacobian is another Callback returning the
chosen gradient route's gradient; equality constraints with a sparse Jacobian (multiple
shooting's defects) are a second pair of the same Callbacks (:func:`search`).  IPOPT runs
with a limited-memory Hessian.  Every Callback is kept referenced on the solver (one
collected early makes IPOPT fail silently with ``Invalid_Number_Detected``), and
``stats()['return_status']`` says how it ended.

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

import casadi as ca
import numpy as np

from ...interrupts import Interrupted, OutOfTime, catching
from ..goal import GoalReached
from ..outcome import ipopt_outcome
from ..ipopt_callbacks import IterationHook, NumericFunction
from .base import LibraryOptions


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


class IpoptOptions(LibraryOptions):
    """IPOPT's options, by its own names: IPOPT itself says which it knows
    (:func:`check_options`); its documentation gives the names to suggest
    (:func:`option_names`)."""

    label = "IPOPT"

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return option_names()

    @classmethod
    def unknown(cls, options) -> list[str]:
        return check_options(options)


def _objective(ev, n) -> NumericFunction:
    """phi(x) from the evaluator ``ev``, its Jacobian ``ev``'s gradient."""
    return NumericFunction("phi", n, ca.Sparsity.dense(1, 1), lambda x: ev(x)[0],
                     ca.Sparsity.dense(1, n), lambda x: ev(x)[1].reshape(1, -1))


def _constraints(con, n) -> NumericFunction:
    """``con.values(x)`` (``con.size`` of them, held at 0), its Jacobian ``con.jacobian(x)``
    (a scipy sparse matrix) read on ``con.pattern``."""
    rows, cols = con.pattern.get_triplet()
    return NumericFunction("g", n, ca.Sparsity.dense(con.size, 1), con.values, con.pattern,
                     lambda x: ca.DM(con.pattern,
                                     np.asarray(con.jacobian(x)[rows, cols]).ravel()))


def ipopt_options(maxiter, tol, options, deadline) -> dict:
    """IPOPT's options for a search: limited-memory Hessian, silent, the time the
    :class:`~.deadline.Deadline` leaves as ``max_wall_time``, the user's ``options`` last."""
    ipopt = {"hessian_approximation": "limited-memory", "max_iter": maxiter, "tol": tol,
             "print_level": 0, "sb": "yes", "limited_memory_max_history": 20}
    if deadline.limit is not None:
        ipopt["max_wall_time"] = deadline.left()
    ipopt.update(options)
    return ipopt


def run(problem, ev, u0, call):
    """Search from ``u0`` with the evaluator ``ev`` (f and gradient asked for separately,
    memoised), as ``call`` (a :class:`~.base.SearchCall`) asks; the deadline becomes IPOPT's
    ``max_wall_time``.  Returns ``(status, message)`` (:mod:`..outcome`); an interrupt raises
    :class:`~casadi_keyframe.interrupts.Interrupted`."""
    status, message, _ = search(ev, u0, problem.bounds(), call.maxiter, call.tol,
                                call.options.as_dict(), lambda x: call.on_iteration(),
                                call.deadline)
    return status, message


def search(ev, x0, bounds, maxiter, tol, options, on_iteration, deadline, *,
           constraints=None, name: str = "keyframe"):
    """IPOPT from ``x0`` within ``bounds`` (``(lower, upper)``) on the evaluator ``ev``'s
    objective, held to ``constraints.values(x) = 0`` when given (an object with ``size``,
    ``values(x)``, ``jacobian(x)`` as a scipy sparse matrix and its CasADi ``pattern``);
    ``on_iteration(x)`` after each iteration with the iterate.  Returns ``(status, message,
    x)`` with IPOPT's last point; an interrupt raises
    :class:`~casadi_keyframe.interrupts.Interrupted`, the goal met :class:`~.goal.GoalReached`."""
    lb, ub = bounds
    n = len(lb)
    X = ca.MX.sym("x", n)
    phi = _objective(ev, n)
    nlp, keep, held = {"x": X, "f": phi(X)}, [phi], {}
    if constraints is not None:
        g = _constraints(constraints, n)
        nlp["g"], held = g(X), {"lbg": 0, "ubg": 0}
        keep.append(g)
    it = IterationHook(n, on_iteration, m=0 if constraints is None else constraints.size)
    ipopt = ipopt_options(maxiter, tol, options, deadline)
    solver = ca.nlpsol(name, "ipopt", nlp, {"ipopt": ipopt, "print_time": False,
                                            "iteration_callback": it, "error_on_fail": False})
    solver._keep = (*keep, it)  # Callbacks must outlive the solver
    # an interrupt CasADi catches inside IPOPT ends it as NonIpopt_Exception_Thrown: the
    # handler's log, the evaluator and the iteration hook say it was one
    with catching(signal.SIGINT) as caught:
        out = solver(x0=x0, lbx=lb, ubx=ub, **held)
    signum = caught.signum or ev.interrupted or it.interrupted
    if signum:
        raise Interrupted(signum)
    if it.reached is not None:
        raise it.reached
    if getattr(ev, "timed_out", False) or it.timed_out:  # a cut evaluation IPOPT swallowed
        raise OutOfTime(deadline)
    status, message = ipopt_outcome(solver.stats().get("return_status", "unknown"),
                                    maxiter=ipopt["max_iter"])
    return status, message, np.asarray(out["x"]).ravel()
