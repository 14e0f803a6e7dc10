"""Where a residual search moves (:class:`SearchSpace`): the evaluator's variables, the bounds
on them and the Jacobian products of a :class:`~.linearization.Linearization` in them."""
from __future__ import annotations

import numpy as np

from .linearization import linearize


class SearchSpace:
    """Where a residual search moves: the evaluator's variables z (a smooth metric's, u =
    S z, the controls themselves, or multiple shooting's controls and nodes), the bounds on
    them, and the Jacobian products in z.  ``method`` names the search in a refusal."""

    def __init__(self, problem, ev, method: str):
        merit = getattr(getattr(ev, "ev", ev), "merit", None)
        self.merit = merit if hasattr(merit, "linearize") else None
        if self.merit is None and not hasattr(problem, "objective_terms"):
            raise ValueError(f"method {method!r} searches residuals; {problem!r} has none")
        self.problem, self.metric = problem, getattr(ev, "metric", None)
        self.lb, self.ub = problem.bounds()
        self.bounded = bool(np.isfinite(self.lb).any() or np.isfinite(self.ub).any())

    def controls(self, z):
        return z if self.metric is None else self.metric.smooth(z)

    def linearize(self, z):
        """The residual map at z: the problem's objective at its controls
        (:func:`~.linearization.linearize`), or the merit's own (multiple shooting's)."""
        if self.merit is not None:
            return self.merit.linearize(z)
        return linearize(self.problem, self.controls(z))

    def products(self, lin, free=1.0, between=lambda: None):
        """``(z -> J_z p, w -> J_z^T w)`` at ``lin``, with only the ``free`` variables moving
        and ``between()`` run before each product."""
        smooth = (lambda v: v) if self.metric is None else self.metric.smooth

        def jvp(d):
            between()
            return lin.jvp(smooth(free * d))

        def vjp(s):
            between()
            return free * smooth(lin.vjp(s))

        return jvp, vjp

    def free(self, z, gradient):
        """1 where a variable may move, 0 at a bound the gradient pushes against."""
        if not self.bounded:
            return 1.0
        return np.where(((z <= self.lb) & (gradient > 0)) | ((z >= self.ub) & (gradient < 0)),
                        0.0, 1.0)

    def clipped(self, z, p):
        return p if not self.bounded else np.clip(z + p, self.lb, self.ub) - z
