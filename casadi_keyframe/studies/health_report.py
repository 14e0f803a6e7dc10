r"""A gradient's health at a point, for any route: :func:`gradient_health` and its printed
form :func:`format_health` (``casadi-keyframe gradcheck``).

It measures the route's backward growth, the dot-product test against one tangent pass,
central differences along the gradient and a random direction, the linearity radius (the
longest step along the gradient whose objective stays within 10 % of its linear model), and
for a route that is not exact its cosine and error against the exact one; its verdict is
``healthy``, ``stiff``, ``approximate``, ``unreliable`` or ``inconsistent``.  What each
measure says and when each verdict is given: ``docs/explanations/gradient_health.md``.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..adjoints import DEFAULT, FiniteDifference, get_gradient
from ..health import (GradientError, GradientRouteWarning, Growth, check_finite, past_bound,
                     refusal)
from ..state import SimulationError

STEPS = (1e-2, 1e-4, 1e-6)  # central-difference steps, times max(|u|, 1)
LINEARITY = 0.1  # the linear model's allowed relative miss for the linearity radius
DOT_TOLERANCE, FD_TOLERANCE = 1e-6, 1e-4  # an exact route's dot test and best difference
APPROXIMATE_COSINE = 0.9  # an approximate route pointing this close to the exact gradient


@dataclass
class HealthReport:
    """A route's gradient at controls ``u`` of a problem: ``value`` and ``norm`` of the
    objective and gradient, ``growth`` (:class:`~casadi_keyframe.health.Growth`, None for a
    route without a watched backward pass), ``refused`` (the guard's message, or None),
    ``dot_test`` (relative), ``differences`` (rows: direction, step, central difference,
    the route's slope, relative error), ``radius`` (the linearity radius; 0 if not even the
    smallest resolvable step; None if not measured), ``versus_exact`` ((relative error,
    cosine) for a route that is not exact), ``exact_growth``, the ``verdict`` with its
    ``reason``, the route's known ``limits`` on this model and its growth ``bound``."""

    problem: str
    route: str
    size: int
    value: float
    norm: float
    growth: Growth | None
    refused: str | None
    dot_test: float
    differences: list = field(default_factory=list)
    radius: float | None = None
    versus_exact: tuple | None = None
    exact_growth: Growth | None = None
    verdict: str = ""
    reason: str = ""
    limits: list = field(default_factory=list)
    bound: float = np.inf

    def best_difference(self, direction: str) -> float:
        """The smallest relative error of the central differences along ``direction``."""
        errors = [r["relative_error"] for r in self.differences if r["direction"] == direction]
        return min(errors) if errors else np.nan


def gradient_health(problem, u=None, route=DEFAULT.name, *, steps=STEPS,
                    directions: int = 1, seed: int = 0, radius: bool = True) -> HealthReport:
    """The :class:`HealthReport` of ``route`` (a name or a route object) on ``problem`` at
    controls ``u`` (default: where the optimizer starts), its guard off so an overflowing
    pass is measured whole; ``steps`` the central differences' steps (times
    ``max(|u|, 1)``), ``directions`` random directions beside the gradient,
    ``radius=False`` skips the linearity radius (a ladder of simulations)."""
    u = problem.initial_controls() if u is None else problem.controls.check(u)
    rng = np.random.default_rng(seed)
    strategy = get_gradient(route).unguarded()
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", GradientRouteWarning)  # the report lists the limits
        found = strategy.evaluate(problem, u)
    value, g, growth = found.value, found.gradient, found.growth
    refused = _refusal(strategy, problem, g, growth)
    exact_g, exact_growth = g, growth
    if not strategy.exact:
        exact = DEFAULT().unguarded().evaluate(problem, u)
        exact_g, exact_growth = exact.gradient, exact.growth
    report = HealthReport(problem.name, route if isinstance(route, str) else strategy.name,
                          problem.size, float(value), float(np.linalg.norm(g)), growth,
                          refused, np.nan, exact_growth=None if exact_g is g else exact_growth,
                          limits=strategy.limits(problem.model), bound=strategy.bound)
    if exact_g is not g:
        report.versus_exact = _compare(g, exact_g)
    scale = max(float(np.linalg.norm(u)), 1.0)
    along = g if np.all(np.isfinite(g)) and report.norm > 0 else exact_g
    random = [_unit(rng.standard_normal(problem.size)) for _ in range(max(directions, 1))]
    tangent = problem.directional_derivative(u, random[0])
    report.dot_test = _relative(_slope(g, random[0]), tangent)
    for name, d in [("gradient", _unit(along))] + [("random", d) for d in random[:directions]]:
        report.differences += _differences(problem, u, g, d, name, [h * scale for h in steps])
    if radius:
        report.radius = linearity_radius(problem, u, value, along, scale)
    report.verdict, report.reason = verdict(report, strategy.exact)
    return report


def _refusal(route, problem, g, growth) -> str | None:
    """The guard's message if the guarded ``route`` would refuse this gradient."""
    if growth is not None and past_bound(growth.growth, route.bound):
        return refusal(route, problem, growth)
    try:
        check_finite(route, g, problem)
    except GradientError as err:
        return str(err)
    return None


def _unit(d):
    return d / np.linalg.norm(d)


def _slope(g, d) -> float:
    with np.errstate(all="ignore"):
        return float(g @ d)


def _relative(value, reference) -> float:
    with np.errstate(all="ignore"):
        return float(abs(value - reference) / max(abs(reference), 1e-300))


def _compare(g, reference) -> tuple[float, float]:
    from .accuracy import relative_error_and_cosine

    with np.errstate(all="ignore"):
        return relative_error_and_cosine(g, reference)


def _differences(problem, u, g, d, name, steps) -> list[dict]:
    """Central differences of the objective along ``d`` at each step, against ``g . d``."""
    rows, slope = [], _slope(g, d)
    for h in steps:
        try:
            difference = FiniteDifference(h).directional(problem, u, d)
        except SimulationError:
            difference = np.nan
        rows.append({"direction": name, "step": h, "difference": difference, "slope": slope,
                     "relative_error": (_relative(slope, difference)
                                        if np.isfinite(difference) else np.nan)})
    return rows


def linearity_radius(problem, u, value: float, g, scale: float, *, tolerance=LINEARITY,
                     largest: float = 1e2) -> float:
    """The largest step ``s`` along ``-g / |g|`` for which every step of the ladder up to it
    keeps ``|phi(u + s d) - phi(u) - s g.d| <= tolerance |s g.d|``; the ladder starts at the
    smallest step whose change in phi round-off cannot hide (0 if that step fails already)
    and rises by sqrt(10) up to ``largest * scale``."""
    d = -_unit(g)
    slope = _slope(g, d)
    if not (np.isfinite(slope) and slope < 0):
        return 0.0
    s = max(1e3 * np.finfo(float).eps * max(abs(value), 1e-300) / abs(slope), 1e-10 * scale)
    passed = 0.0
    while s <= largest * scale:
        try:
            change = problem.objective(u + s * d) - value
        except SimulationError:
            break
        if not abs(change - s * slope) <= tolerance * abs(s * slope):
            break
        passed, s = s, s * np.sqrt(10.0)
    return passed


def verdict(report: HealthReport, exact: bool) -> tuple[str, str]:
    """``(verdict, reason)`` of a report (module docstring)."""
    if report.refused:
        return "unreliable", report.refused
    if not exact:
        rel, cos = report.versus_exact
        if cos < APPROXIMATE_COSINE:
            return "unreliable", (f"cosine {cos:.3f} against the exact {DEFAULT.name} (relative "
                                  f"error {rel:.2g}): it points elsewhere; use --gradient "
                                  f"{DEFAULT.name}")
        return "approximate", (f"cosine {cos:.4f}, relative error {rel:.2g} against the exact "
                               f"{DEFAULT.name}")
    if not report.dot_test <= DOT_TOLERANCE:
        return "inconsistent", (f"the adjoint and the tangent pass disagree by "
                                f"{report.dot_test:.2g}: a bug in a backward or tangent step")
    best = max(report.best_difference("gradient"), report.best_difference("random"))
    if not best <= FD_TOLERANCE:
        return "stiff", (f"exact (dot test {report.dot_test:.1e}), but central differences "
                         f"agree only to {best:.2g} at the steps tried: the objective is linear "
                         f"only within {_radius(report.radius)} along the gradient")
    return "healthy", (f"exact (dot test {report.dot_test:.1e}), central differences agree to "
                       f"{best:.1e}" + ("" if report.radius is None else
                                        f"; linear within {_radius(report.radius)} along "
                                        "the gradient"))


def _radius(radius) -> str:
    if radius is None:
        return "(not measured)"
    return "less than the smallest resolvable step" if radius == 0 else f"{radius:.2g}"


def format_health(report: HealthReport) -> str:
    """The report as a short table and a verdict line."""
    lines = [f"gradient health of '{report.route}' on {report.problem} ({report.size} "
             f"controls)", f"  objective                  {report.value:.6g}",
             f"  gradient norm              {report.norm:.3g}"]
    lines.append(f"  backward growth            {_growth(report.growth, report.bound)}")
    if report.exact_growth is not None:
        label = f"exact {DEFAULT.name}'s"
        lines.append(f"    {label:25s}{_growth(report.exact_growth, DEFAULT.bound)}")
    lines.append(f"  dot test (vs tangent)      {report.dot_test:.2e}")
    if report.versus_exact is not None:
        rel, cos = report.versus_exact
        label = f"vs exact {DEFAULT.name}"
        lines.append(f"  {label:27s}cosine {cos:.4f}, relative error {rel:.3g}")
    steps = sorted({r["step"] for r in report.differences}, reverse=True)
    lines.append("  central differences, step " + "".join(f"{h:>10.0e}" for h in steps))
    for name in dict.fromkeys(r["direction"] for r in report.differences):
        errors = {r["step"]: r["relative_error"] for r in report.differences
                  if r["direction"] == name}
        lines.append(f"    along {name:9s} rel. err " + "".join(f"{errors[h]:>10.1e}"
                                                             for h in steps))
    if report.radius is not None:
        lines.append(f"  linearity radius           {_radius(report.radius)} (a step, in the "
                     f"controls' norm, within {LINEARITY:.0%} of the linear model)")
    if report.limits:
        lines.append(f"  known limits               {'; '.join(report.limits)}")
    lines.append(f"verdict: {report.verdict.upper()}: {report.reason}")
    return "\n".join(lines)


def _growth(growth, bound: float) -> str:
    if growth is None:
        return "not watched (no backward loop of its own)"
    held = f"bound {bound:.0e}" if np.isfinite(bound) else "exact: refused only if not finite"
    return (f"{growth.growth:.3g} by frame {growth.frame} ({held}); "
            f"fastest x{growth.fastest:.3g} in step {growth.fastest_step}")


def compare_routes(problem, u, names) -> str:
    """Each route's gradient at ``u`` and its time against the last route's (``gradcheck
    --routes``): relative error and cosine, one line each."""
    from .accuracy import relative_error_and_cosine

    routes = {}
    for name in names:
        t = time.perf_counter()
        routes[name] = (get_gradient(name)(problem, u)[1], time.perf_counter() - t)
    lines = [f"routes against '{names[-1]}':"]
    for name, (g, sec) in routes.items():
        rel, cos = relative_error_and_cosine(g, routes[names[-1]][0])
        lines.append(f"  {name:8s} {sec:8.3f} s   relative error {rel:.3e}   cosine {cos:.12f}")
    return "\n".join(lines)
