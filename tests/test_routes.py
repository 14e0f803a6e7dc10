"""Gradient routes as objects that carry their facts (the third architecture pass): every
registered route states them, the command line's help is written from the registry, and a
new route is one class plus one registry entry: the health guard, the health report and a
search's summary ask it, never its name."""
import math

import numpy as np
import pytest
from helpers import small_flock

from casadi_keyframe import solve
from casadi_keyframe.adjoints import (DEFAULT, DEPRECATED, GRADIENTS, ROUTES, Evaluation,
                                      Route, get_gradient, route_help)
from casadi_keyframe.health import GROWTH_BOUND, GradientError, check_finite
from casadi_keyframe.studies.health_report import format_health, gradient_health


def test_every_route_states_its_facts():
    for name, route in GRADIENTS.items():
        assert issubclass(route, Route) and route.name == name and route.help, name
        first = route.__doc__.split(":")[0]
        assert first in (("Exact", "Exact, the reference") if route.exact else
                         ("APPROXIMATE", "Central differences with step ``h``")), name
        assert route.bound == (GROWTH_BOUND if first == "APPROXIMATE" else math.inf), name
    assert DEFAULT.exact and DEFAULT.name in GRADIENTS
    assert ROUTES == (*GRADIENTS, *DEPRECATED)
    for old, route in DEPRECATED.items():
        assert route.replaced_by.name in GRADIENTS
        with pytest.warns(DeprecationWarning, match=f"'{route.replaced_by.name}'"):
            assert type(get_gradient(old)) is route.replaced_by


def test_the_command_lines_help_names_every_route_and_the_deprecated_names():
    text = route_help()
    assert text.startswith(f"gradient route (default: the problem's SOLVE, else '{DEFAULT.name}')")
    for name, route in GRADIENTS.items():
        assert f"'{name}' {route.help}" in text
    assert "('exact' is a deprecated name of 'casadi')" in text
    assert route_help("the route checked").startswith("the route checked (default")


class Tangent(Route):
    """Exact: one tangent-linear pass per control (forward mode), a sixth route written as a
    new route is: its own class, its facts, one registry entry."""

    name = "tangent"
    exact = True
    help = "forward mode, one tangent pass per control"

    def evaluate(self, problem, u):
        eye = np.eye(u.size)
        grad = np.array([problem.directional_derivative(u, e) for e in eye])
        check_finite(self, grad, problem)
        return Evaluation(problem.objective(u), grad)

    def likely_cause(self, model) -> str:
        return "a tangent pass overflowed. Fix: use --gradient adjoint"


def test_a_new_route_is_one_class_and_one_registry_entry(monkeypatch):
    monkeypatch.setitem(GRADIENTS, "tangent", Tangent)
    assert "'tangent' forward mode, one tangent pass per control" in route_help()
    prob = small_flock(n=4, steps=8)
    u = 0.1 * np.random.default_rng(0).standard_normal(prob.size)
    exact = prob.objective_and_gradient(u, "adjoint")[1]
    assert np.allclose(prob.objective_and_gradient(u, "tangent")[1], exact, rtol=1e-9,
                       atol=1e-12 * np.abs(exact).max())
    report = gradient_health(prob, u, "tangent", radius=False)
    assert report.verdict == "healthy" and report.limits == [] and report.bound == math.inf
    assert "not watched" in format_health(report)
    summary = solve(prob, gradient="tangent", maxiter=3, quiet=True).summary()
    assert summary["gradient"] == "tangent" and summary["gradient_health"]["bound"] is None
    with pytest.raises(GradientError, match="gradient 'tangent' refused.*a tangent pass") as err:
        check_finite(Tangent(), np.array([np.nan]), prob)
    assert err.value.route == "tangent"
