"""scipy's trust-region reflective ``least_squares`` on the objective's residuals, matrix-free.

Its ``fun`` is the residual vector r (one simulation that keeps its records,
:class:`~..residual.linearization.Linearization`) and its ``jac`` a ``LinearOperator`` of the exact
products on that run; ``tr_solver="lsmr"``: each step solves the damped Gauss-Newton
problem by LSMR, then the trust region is searched in the plane of that step and the
gradient, so a rejected step costs one simulation.  Bounds are scipy's own (reflective).

Its iterations reach the evaluator through ``callback``: each accepted point is evaluated
there (the best point, history, checkpoint, goal), so a run costs one more simulation and
backward pass per iteration than scipy's own count.  ``options`` go to ``least_squares``
over this module's defaults (``max_nfev = 10 * maxiter``, ``ftol = tol``, ``xtol = 1e-10``,
``gtol = 1e-10``, ``x_scale = 1``) and ``lsmr_maxiter`` (50), LSMR's iterations per step.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse.linalg import LinearOperator

from ...interrupts import check
from ..outcome import CONVERGED, FAILED, LIMIT
from ..residual.space import SearchSpace
from .base import LibraryOptions

OPTIONS = ("max_nfev", "ftol", "xtol", "gtol", "x_scale", "lsmr_maxiter")


def option_names() -> tuple[str, ...]:
    return OPTIONS


class LeastSquaresOptions(LibraryOptions):
    """``least_squares``' options (:data:`OPTIONS`: scipy's, and ``lsmr_maxiter``)."""

    label = "scipy's least_squares"

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return option_names()


class _Stop(Exception):
    """The deadline passed inside scipy (raised through it)."""


class _Residuals:
    """scipy's ``fun`` and ``jac`` in the search's variables: the last point's
    linearization, and the one its Jacobian operator was made at (scipy keeps using that
    operator while it tries points), kept for their products; simulations and products
    counted."""

    def __init__(self, space, between):
        self.space, self.between = space, between
        self.lin = self.z = self.jac_lin = None
        self.simulations = self.products = 0

    def at(self, z):
        z = np.asarray(z, dtype=float)
        if self.lin is None or not np.array_equal(self.z, z):
            if self.lin is not self.jac_lin:
                self._drop(self.lin)
            self.between()
            self.lin, self.z = self.space.linearize(z), z.copy()
            self.simulations += 1
        return self.lin

    def residual(self, z):
        return self.at(z).residual

    def jacobian(self, z, *_):
        lin = self.at(z)
        if self.jac_lin is not lin:
            self._drop(self.jac_lin)
            self.jac_lin = lin
        jvp, vjp = self.space.products(lin, 1.0, self.between)
        return LinearOperator(lin.shape, matvec=jvp, rmatvec=vjp, dtype=float)

    def _drop(self, lin) -> None:
        if lin is not None:
            self.products += lin.products
            lin.release()

    def release(self) -> None:
        self._drop(self.lin)
        if self.jac_lin is not self.lin:
            self._drop(self.jac_lin)
        self.lin = self.jac_lin = None

    def tagged(self, message: str) -> str:
        return (f"{message} [least_squares: {self.simulations} linearizations, "
                f"{self.products} Jacobian products]")


def run(problem, ev, u0, call):
    """Search from ``u0`` with scipy's ``least_squares`` (method "trf", LSMR), evaluating
    each accepted point with ``ev``, as ``call`` (a :class:`~.base.SearchCall`) asks.
    Returns ``(status, message)``."""
    maxiter, on_iteration, deadline = call.maxiter, call.on_iteration, call.deadline
    space = SearchSpace(problem, ev, "least-squares")
    opts = {"max_nfev": 10 * maxiter, "ftol": call.tol, "xtol": 1e-10, "gtol": 1e-10,
            "x_scale": 1.0, "lsmr_maxiter": 50, **call.options.as_dict()}

    def between():
        check()
        if deadline.passed():
            raise _Stop

    residuals, count = _Residuals(space, between), [0]

    def callback(intermediate_result):
        ev(intermediate_result.x)
        count[0] += 1
        on_iteration()
        if count[0] >= maxiter:
            raise StopIteration

    bounds = (space.lb, space.ub) if space.bounded else (-np.inf, np.inf)
    lsmr = {"maxiter": opts.pop("lsmr_maxiter")}
    try:
        out = least_squares(residuals.residual, np.array(u0, dtype=float),
                            jac=residuals.jacobian, bounds=bounds, method="trf",
                            tr_solver="lsmr", tr_options=lsmr, callback=callback, **opts)
    except _Stop:
        return LIMIT, residuals.tagged("time limit reached before converging")
    finally:
        residuals.release()
    status, message = outcome(out.status, maxiter, opts["max_nfev"])
    return status, residuals.tagged(message)


def outcome(status: int, maxiter: int, max_nfev: int) -> tuple[int, str]:
    """``(status, sentence)`` for ``least_squares``' ``status``."""
    if status == -2:
        return LIMIT, f"iteration limit reached ({maxiter}) before converging"
    if status == 0:
        return LIMIT, f"evaluation limit reached ({max_nfev}) before converging"
    if status == 1:
        return CONVERGED, "converged: the gradient vanished (gtol)"
    if status in (2, 4):
        return CONVERGED, "converged: the objective stopped decreasing (ftol)"
    if status == 3:
        return FAILED, ("search failed: the trust region shrank below xtol: the objective "
                        "does not follow its linear model at a larger scale (a spring's law "
                        "switching inside a linearized step, a contact)")
    return FAILED, f"least_squares stopped without converging (status {status})"
