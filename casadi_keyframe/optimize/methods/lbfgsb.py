"""L-BFGS-B (scipy's ``minimize``) as a search method: bounds on the controls, a
limited-memory quasi-Newton step, and one restart from the best point when a line search
fails after progress.

``options`` go to ``minimize``'s L-BFGS-B options over this module's defaults
(``maxfun = 10 * maxiter``, ``ftol = tol``, ``gtol = 1e-10``, ``maxcor = 20``); their names
are read from scipy's own documentation of the method (:func:`option_names`).
"""
from __future__ import annotations

import functools
import re

import numpy as np
from scipy.optimize import minimize, show_options

from ..outcome import FAILED, LIMIT, lbfgsb_outcome
from .base import LibraryOptions


@functools.cache
def option_names() -> tuple[str, ...]:
    """The options scipy's L-BFGS-B takes, from its documentation
    (``scipy.optimize.show_options("minimize", "L-BFGS-B")``), in its order."""
    text = show_options("minimize", "L-BFGS-B", disp=False)
    _, found, section = text.partition("Options\n-------\n")
    section = re.split(r"\n(?:Notes|References|Examples)\n-+\n", section)[0]
    names = tuple(re.findall(r"^(\w+) :", section, re.M))
    if not (found and names):  # a scipy whose documentation reads otherwise: do not guess
        raise RuntimeError("could not read L-BFGS-B's option names from scipy's "
                           "show_options('minimize', 'L-BFGS-B'); please report the scipy "
                           "version")
    return names


class LbfgsbOptions(LibraryOptions):
    """L-BFGS-B's options, by scipy's names (:func:`option_names`)."""

    label = "scipy's L-BFGS-B"

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return option_names()


class _TimeUp(Exception):
    """Raised from L-BFGS-B's callback past the deadline (scipy lets it through)."""


def run(problem, ev, u0, call):
    """Search from ``u0`` with the evaluator ``ev`` (f and gradient together), as ``call``
    (a :class:`~.base.SearchCall`) asks.  Returns ``(status, message)`` (:mod:`..outcome`)."""
    maxiter, on_iteration, deadline = call.maxiter, call.on_iteration, call.deadline
    opts = {"maxiter": maxiter, "maxfun": 10 * maxiter, "ftol": call.tol, "gtol": 1e-10,
            "maxcor": 20}
    opts.update(call.options.as_dict())
    lb, ub = problem.bounds()
    bounds = list(zip(lb, ub)) if np.isfinite(lb).any() or np.isfinite(ub).any() else None

    def callback(intermediate_result):
        on_iteration()
        if deadline.passed():
            raise _TimeUp

    try:
        res = minimize(ev, u0, jac=True, method="L-BFGS-B", bounds=bounds, options=opts,
                       callback=callback)
        budget = {"maxiter": opts["maxiter"], "maxfun": opts["maxfun"]}  # this stage's
        status, message = lbfgsb_outcome(res.message, **budget)
        # a line search that fails after progress restarts from the best point with no
        # curvature memory: its first step is along the steepest descent, so a second
        # failure there means no step lowers phi (a kink, such as the cloth law's at rest
        # length, or round-off); one that fails at the first step leaves the gradient suspect
        if not (status == FAILED and _line_search_failed(res)
                and 0 < res.nit < opts["maxiter"] and res.nfev < opts["maxfun"]):
            return status, message
        opts["maxiter"] -= res.nit
        opts["maxfun"] -= res.nfev
        again = minimize(ev, ev.best_u, jac=True, method="L-BFGS-B", bounds=bounds,
                         options=opts, callback=callback)
    except _TimeUp:
        return LIMIT, "time limit reached before converging"
    if _line_search_failed(again) and again.nit == 0:
        return FAILED, ("line search failed: no step along the steepest descent lowers the "
                        "objective (it failed, and again from the best point with fresh "
                        "curvature memory): a kink of the objective or its round-off floor "
                        f"[L-BFGS-B: {again.message}]")
    return lbfgsb_outcome(again.message, **budget)


def _line_search_failed(res) -> bool:
    return str(res.message).upper().startswith("ABNORMAL")
