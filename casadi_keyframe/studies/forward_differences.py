"""The forward pass as the judge of a gradient: central differences of the objective along a
direction, taken only where they are stable.

:func:`stable_difference` takes the central-difference quotient ``(phi(u + h d) - phi(u -
h d)) / 2h`` over a ladder of steps a decade apart, each refined once by Richardson's
extrapolation (``(4 q(h) - q(2h)) / 3``: fourth order, so a curved objective's truncation
error does not hide a wrong gradient), and finds the widest run of consecutive steps over
which the quotients agree with one another within ``tolerance``: there the objective is
smooth at the scale of h and the quotient is its derivative.  A run shorter than
``decades`` decades is not stable (a kink, a switch of a discrete decision within the
ladder, or round-off): it is kept for what it says, but nothing is claimed from it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..state import SimulationError

LADDER = tuple(10.0 ** -k for k in range(2, 11))  # the steps tried, times |d| = 1
DECADES = 3  # a quotient is stable over at least this many decades of h
TOLERANCE = 1e-5  # relative agreement of the quotients within the stable window


@dataclass(frozen=True)
class StableDifference:
    """A central difference of the forward pass along a direction: ``quotients`` per
    ``steps`` (NaN where a simulation failed), ``window`` the (largest, smallest) step of
    the widest run of agreeing quotients (None: no two agree), ``value`` the run's median
    quotient (NaN: none), ``spread`` its quotients' largest relative difference and
    ``stable`` whether it spans the decades asked."""

    steps: tuple
    quotients: tuple
    window: tuple | None
    value: float
    spread: float
    stable: bool = False

    def error(self, slope: float) -> float:
        """The relative error of a route's ``slope`` ``g . d`` against the stable quotient."""
        return abs(slope - self.value) / max(abs(self.value), 1e-300)

    def describe(self) -> str:
        if self.window is None:
            return "no two quotients agree"
        run = f"h {self.window[0]:.0e}..{self.window[1]:.0e} (spread {self.spread:.1e})"
        return run if self.stable else f"NOT STABLE: only {run}"


def _quotient(objective, h: float) -> float:
    try:
        near = (objective(h) - objective(-h)) / (2 * h)
        far = (objective(2 * h) - objective(-2 * h)) / (4 * h)
    except SimulationError:
        return np.nan
    return (4 * near - far) / 3


def stable_difference(problem, u, d, *, steps=LADDER, decades: int = DECADES,
                      tolerance: float = TOLERANCE) -> StableDifference:
    """The :class:`StableDifference` of ``problem``'s objective at controls ``u`` along
    ``d`` (module docstring; the steps are in units of ``d``, so a unit ``d`` is best)."""
    d = np.asarray(d, float)
    q = np.array([_quotient(lambda s: problem.objective(u + s * d), h) for h in steps])
    best = None
    for first in range(len(q)):
        for last in range(len(q) - 1, first, -1):
            run = q[first:last + 1]
            if not np.all(np.isfinite(run)):
                continue
            spread = (run.max() - run.min()) / max(np.abs(np.median(run)), 1e-300)
            if spread <= tolerance:
                if best is None or last - first > best[1] - best[0]:
                    best = (first, last, spread)
                break
    if best is None:
        return StableDifference(tuple(steps), tuple(q), None, np.nan, np.nan)
    first, last, spread = best
    span = np.log10(steps[first] / steps[last])
    return StableDifference(tuple(steps), tuple(q), (steps[first], steps[last]),
                            float(np.median(q[first:last + 1])), float(spread),
                            bool(span >= decades - 1e-9))
