"""A trust region on the Gauss-Newton model of the objective's residuals, matrix-free: the
descent :class:`~..residual.descents.SteihaugPath` sized by the rule
:class:`~..residual.steps.TrustRadius`, on the objective's
:class:`~..residual.linearization.Linearization`.

The objective is ``0.5 |r(u)|^2``.  At each point the model
``0.5 |r + J p|^2`` is minimised by conjugate gradients on ``J^T J p = -J^T r`` from p = 0
(CGLS: per iteration one tangent pass and one backward pass), stopped where the path leaves
the trust region (Steihaug).  A step the model does not predict is rejected and the region
shrinks; the next trial is the same path cut shorter, one evaluation and no new products.

``options`` (:class:`GaussNewtonOptions`): ``inner_maxiter`` CG iterations per step, ``inner_tol`` its
relative tolerance on the model's gradient, ``radius`` the first radius (None: the first
step unbounded), ``accept`` the least ratio of actual to predicted decrease that takes a
step, ``maxfun`` evaluations (default ``10 * maxiter``), ``gtol`` the gradient's largest
component that counts as zero, ``plane`` (default True) a cut step chosen in the plane of
the gradient and the Gauss-Newton step too.  Bounds hold by fixing the controls at a bound
the gradient pushes against and clipping the step.  The products are exact whatever gradient route the
evaluator runs for its bookkeeping.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...interrupts import check
from ..outcome import CONVERGED, FAILED, LIMIT
from ..residual.descents import SteihaugPath
from ..residual.space import SearchSpace
from ..residual.steps import TrustRadius
from ..options import TypedOptions, real, whole

@dataclass(frozen=True)
class GaussNewtonOptions(TypedOptions):
    """The Gauss-Newton trust region's options (the module docstring says each)."""

    label: ClassVar[str] = "Gauss-Newton"
    CHECKS: ClassVar[dict] = {
        "inner_maxiter": ("a whole number >= 1", lambda v: whole(v) and v >= 1),
        "inner_tol": ("a number in (0, 1)", lambda v: real(v) and 0 < v < 1),
        "radius": ("a number > 0 or None", lambda v: v is None or (real(v) and v > 0)),
        "accept": ("a number in [0, 0.25)", lambda v: real(v) and 0 <= v < 0.25),
        "maxfun": ("a whole number >= 1 or None", lambda v: v is None or (whole(v)
                                                                            and v >= 1)),
        "gtol": ("a number >= 0", lambda v: real(v) and v >= 0),
        "plane": ("True or False", lambda v: isinstance(v, bool))}

    inner_maxiter: int = 50
    inner_tol: float = 0.1
    radius: float | None = None
    accept: float = 1e-4
    maxfun: int | None = None
    gtol: float = 1e-10
    plane: bool = True


class _Ended(Exception):
    """The search ends here: ``status`` and ``message`` (:mod:`.outcome`)."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


def run(problem, ev, u0, call):
    """Search from ``u0`` with the evaluator ``ev`` (its objective at each trial point), as
    ``call`` (a :class:`~.base.SearchCall`) asks, ``on_iteration`` after each step taken.
    Returns ``(status, message)`` (:mod:`..outcome`)."""
    maxiter, tol, deadline = call.maxiter, call.tol, call.deadline
    space, counts = SearchSpace(problem, ev, "gauss-newton"), _Counts()
    opts = call.options.as_dict()
    opts["maxfun"] = opts["maxfun"] or 10 * maxiter

    def between():
        check()
        if deadline.passed():
            raise _Ended(LIMIT, "time limit reached before converging")

    z, radius = np.array(u0, dtype=float), TrustRadius(opts["radius"], opts["accept"])
    try:
        for _ in range(maxiter):
            z, before, after, cut = _one_step(ev, space, z, radius, opts, between, counts)
            call.on_iteration()
            if before - after > tol * max(abs(before), abs(after), 1.0):
                continue
            if cut is not None:  # small only because the region is: the model fails there
                raise _Ended(FAILED, _collapsed(*cut))
            raise _Ended(CONVERGED, "converged: the objective stopped decreasing "
                                    "(relative reduction below tol)")
    except _Ended as end:
        return end.status, counts.tagged(end.message)
    return LIMIT, counts.tagged(f"iteration limit reached ({maxiter}) before converging")


class _Counts:
    """What the search did beyond the evaluator's evaluations."""

    def __init__(self):
        self.linearizations = self.products = 0

    def tagged(self, message: str) -> str:
        return (f"{message} [Gauss-Newton: {self.linearizations} linearizations, "
                f"{self.products} Jacobian products]")


def _one_step(ev, space, z, radius, opts, between, counts):
    """One step of the trust region from z, the descent :class:`SteihaugPath` sized by the
    rule ``radius`` (a :class:`~..residual.steps.TrustRadius`): ``(z, f before, f after,
    cut)``, ``cut`` the step's and the full step's lengths where the region cut it to a
    tenth or less; raises :class:`_Ended` where the search ends."""
    lin = space.linearize(z)
    counts.linearizations += 1
    try:
        f = lin.value
        gradient = space.products(lin, 1.0, between)[1](lin.residual)
        if np.max(np.abs(gradient), initial=0.0) <= opts["gtol"]:
            raise _Ended(CONVERGED, "converged: the gradient vanished (below gtol)")
        free = space.free(z, gradient)
        jvp, vjp = space.products(lin, free, between)
        bound = None if opts["plane"] else radius.size  # the plane needs the path's end
        path = SteihaugPath(jvp, vjp, lin.residual, free * gradient, bound,
                            opts["inner_maxiter"], opts["inner_tol"], opts["plane"])
        full = np.linalg.norm(path.step(None)[0]) if path.segments else 0.0
        while True:
            p, model = path.step(radius.size)
            if p is None:
                raise _Ended(CONVERGED, "converged: no free direction lowers the model")
            clipped = space.clipped(z, p)
            if clipped is not p:
                p, model = clipped, 0.5 * np.sum((lin.residual + jvp(clipped)) ** 2)
            predicted, length = f - model, np.linalg.norm(p)
            if full <= 1e-14 * (1 + np.linalg.norm(z)):
                raise _Ended(FAILED, _too_sensitive(full, gradient))
            if not predicted > 0 or length <= 1e-14 * (1 + np.linalg.norm(z)):
                raise _Ended(FAILED, _collapsed(length, full))
            if getattr(ev, "ev", ev).nfev >= opts["maxfun"]:
                raise _Ended(LIMIT, f"evaluation limit reached ({opts['maxfun']}) before "
                                    "converging")
            f_new = ev(z + p)[0]
            if radius.judge((f - f_new) / predicted, length):
                cut = (length, full) if length < 0.1 * full else None
                return z + p, f, f_new, cut
    finally:
        counts.products += lin.products
        lin.release()


def _too_sensitive(full, gradient) -> str:
    return (f"search failed: the Gauss-Newton step ({full:.3g}) is below the controls' "
            f"round-off, the gradient being {np.linalg.norm(gradient):.3g}: the motion "
            "grows so fast with the controls over the horizon that no single-shooting "
            "step resolves it (the health watch's backward growth); shorten the horizon "
            "the gradient crosses (multiple shooting, --segments) or start elsewhere")


def _collapsed(length, full) -> str:
    return (f"search failed: the trust region collapsed (a step of {length:.3g} where the "
            f"Gauss-Newton step is {full:.3g}): the objective does not follow its linear "
            "model beyond that, so it jumps or bends at a smaller scale (a spring's law "
            "switching inside a linearized step, a contact) or the products are wrong "
            "(gradcheck)")
