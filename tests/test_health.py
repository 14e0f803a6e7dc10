"""Gradient health (issue 25): a route whose backward pass overflows fails the evaluation
with a message naming the route, where and the fix; the optimizer steps back from it; a
healthy route never trips the guard on any shipped problem; the health report's verdicts."""
import json
import warnings

import numpy as np
import pytest

from casadi_keyframe import Adjoint, Swapped, load_problem, solve
from casadi_keyframe.adjoints import get_gradient
from casadi_keyframe.cli import main
from casadi_keyframe.health import (GROWTH_BOUND, BackwardWatch, GradientError,
                                    GradientRouteWarning, warn_route_limits)
from casadi_keyframe.studies.health_report import gradient_health
from casadi_keyframe.loading import list_problems
from casadi_keyframe.optimize.evaluator import Evaluator
from casadi_keyframe.scenes.sheets import contact_problem, hanging_sheet
from casadi_keyframe.state import SimulationError, State

# the case (1e53 before the guard), under the paper's penalty springs: the default
# hold keeps the cape on the moving capsules' layer, clear of the springs' curvature
CAPE = {"rows": 6, "cols": 4, "guess": "passive", "collision": "penalty"}


@pytest.fixture(scope="module")
def cape():
    return load_problem("cape_blend", **CAPE)


def test_the_swapped_route_refuses_its_overflow_near_the_capes_capsules(cape):
    u = cape.initial_controls()
    with pytest.warns(GradientRouteWarning, match="curved bodies \\(capsules\\)"):
        with pytest.raises(GradientError) as caught:
            cape.objective_and_gradient(u, "swapped")
    text = str(caught.value)
    assert "gradient 'swapped' refused" in text and "of 60" in text
    assert "by frame" in text and "fastest at step" in text
    assert "curved bodies" in text and "--gradient adjoint" in text
    assert caught.value.route == "swapped" and caught.value.growth > GROWTH_BOUND
    exact = get_gradient("adjoint").evaluate(cape, u)  # the exact route stays within its bound
    assert np.all(np.isfinite(exact.gradient)) and exact.growth.growth < GROWTH_BOUND


def test_gradcheck_prints_the_growth_and_calls_the_swapped_route_unreliable(capsys):
    args = [f"--set={k}={v}" for k, v in CAPE.items()]
    assert main(["gradcheck", "cape_blend", *args, "--gradient", "swapped", "--directions",
                 "0", "--no-radius"]) == 0
    out = capsys.readouterr().out
    growth = next(line for line in out.splitlines() if "backward growth" in line)
    assert float(growth.split()[2]) > GROWTH_BOUND  # refused at the passive start
    assert "verdict: UNRELIABLE: gradient 'swapped' refused" in out
    assert "known limits" in out and "exact adjoint's" in out


@pytest.mark.parametrize("problem, overrides", [
    ("flock_race", {"agents": 8, "steps": 30}),
    ("cloth_shapes", {"rows": 5, "cols": 5, "steps": 30}),  # the hanging sheet
])
def test_gradcheck_calls_the_exact_route_healthy(problem, overrides, capsys):
    args = [f"--set={k}={v}" for k, v in overrides.items()]
    assert main(["gradcheck", problem, *args]) == 0
    out = capsys.readouterr().out
    assert "verdict: HEALTHY: exact" in out and "linearity radius" in out


def test_the_swapped_route_on_a_hanging_sheet_is_approximate():
    prob = contact_problem(rows=4, horizon=1 / 6)
    report = gradient_health(prob, route="swapped", radius=False)
    rel, cos = report.versus_exact
    assert report.verdict == "approximate" and cos > 0.95 and rel < 0.5
    assert report.refused is None and report.growth.growth < 1e3
    assert report.dot_test > 1e-4  # the approximation shows: it is no adjoint of the tangent


def test_the_watch_measures_growth_against_what_was_fed_in():
    class Stub:
        dt, steps, model = 0.5, 3, None

    watch = BackwardWatch(Adjoint(), Stub())
    gx, gv = np.zeros((4, 1, 1)), np.zeros((4, 1, 1))
    gv[3], gv[1] = 1.0, 100.0  # |s_3| = 1, |s_1| = 100
    watch.start(gx, gv)
    one = np.ones((1, 1))

    def step(n, pulled):
        watch.step(n, State(0 * one, pulled * one), State(gx[n], pulled + gv[n]))

    step(2, 10.0)  # pulled back to 10: growth 10, fastest x10
    step(1, 50.0)  # 50 of the largest source after frame 1 (1): growth 50; then s_1 joins
    step(0, 200.0)  # 200 of 100: growth 2
    result = watch.result()
    assert result.growth == pytest.approx(50.0) and result.frame == 1
    assert result.fastest == pytest.approx(10.0) and result.fastest_step == 2
    with pytest.raises(GradientError, match="overflowed"):
        step(0, np.inf)


class Exploding(Adjoint):
    """The exact route, except that evaluations number ``bad`` overflow: their backward step
    multiplies the adjoint by 1e10 (past a float's range within the horizon)."""

    def __init__(self, bad):
        super().__init__()
        self.bad, self.calls = set(bad), 0

    def evaluate(self, problem, u):
        self.calls += 1
        return super().evaluate(problem, u)

    def backward_step(self, integrator):
        exact = integrator.step_vjp
        if self.calls not in self.bad:
            return exact

        def overflowing(*args):
            a, g = exact(*args)
            return State(1e10 * a.x, 1e10 * a.v), 1e10 * g
        return overflowing


def amplified(route, factor):
    """``route`` (a class) running the exact route's backward steps, each multiplying the
    adjoint by ``factor``: its facts (bound, likely cause) stay the route's."""
    class Amplified(route):
        def backward_step(self, integrator):
            def step(*args):
                a, g = integrator.step_vjp(*args)
                return State(factor * a.x, factor * a.v), factor * g
            return step
    return Amplified()


def test_an_exact_route_is_refused_only_when_not_finite_an_approximate_one_past_its_bound():
    """A growth of about 1e10 (1.6 per step over 50 steps) is on record for an exact route
    (a sensitive motion, still its exact derivative) and refused for the swapped one."""
    race = load_problem("flock_race", agents=8, steps=50)
    u = race.initial_controls()
    exact = amplified(Adjoint, 1.6)
    found = exact.evaluate(race, u)
    assert GROWTH_BOUND < found.growth.growth < exact.bound
    assert np.all(np.isfinite(found.gradient))
    with pytest.raises(GradientError, match="bound 1e\\+08") as caught:
        amplified(Swapped, 1.6)(race, u)
    assert caught.value.route == "swapped" and "swapped adjoint updates" in str(caught.value)


def test_the_optimizer_steps_back_from_a_refused_gradient():
    race = load_problem("flock_race", agents=8, steps=40)
    ev = Evaluator(race, Exploding({2}), None)
    u0 = race.initial_controls()
    f0, g0 = ev(u0)
    f1, g1 = ev(u0 + 0.1)  # refused: a finite value above the best, no gradient
    assert f1 > f0 and not np.any(g1) and ev.failures == 1 and ev.health.refused == 1
    result = solve(race, gradient=Exploding({3, 4}), maxiter=30, quiet=True)
    stage = result.stages[0]
    assert stage["gradient_refused"] == 2 and stage["failed_simulations"] == 2
    assert result.nit > 10 and result.fun < 0.2 * f0  # the search went on past them
    assert np.all(np.isfinite(result.jac))
    assert all(r["gradient_growth"] < 1e3 for r in result.history)
    health = result.summary()["gradient_health"]
    assert health["refused"] == 2 and health["bound"] is None  # exact: only when not finite
    assert health["largest_growth"] > GROWTH_BOUND  # the refused ones' growth is on record


# every shipped problem, reduced: its own route, at its start and at a perturbed point
REDUCED = {
    "flock_path": {"agents": 10, "steps": 30},
    "flock_race": {"agents": 8, "steps": 30},
    "flock_shapes": {"agents": 20, "steps": 40},
    "cloth_shapes": {"rows": 5, "cols": 5, "steps": 30},
    "cloth_arch": {"rows": 5, "cols": 5, "steps": 30},
    "cloth_toss": {"rows": 6, "cols": 6},
    "cape_blend": {"rows": 6, "cols": 4},
    "mesh_keyframes": {},
}


def test_every_shipped_problem_is_in_the_false_alarm_check():
    assert set(REDUCED) == {name for name, _ in list_problems()}


@pytest.mark.parametrize("name", sorted(REDUCED))
def test_a_healthy_route_never_trips_the_guard(name):
    prob = load_problem(name, **REDUCED[name])
    rng = np.random.default_rng(0)
    masses = np.repeat(prob.model.masses, prob.model.dim)
    start = prob.initial_controls()
    routes = ["adjoint"] + ([] if Swapped().limits(prob.model)
                            or not hasattr(prob.integrator, "swapped_step_vjp") else ["swapped"])
    nearby = start + 0.1 * rng.standard_normal(prob.size) * _per_control(prob, masses)
    for u in (start, nearby):
        for route in routes:
            strategy = Adjoint() if route == "adjoint" else None
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("error", GradientRouteWarning)
                    found = (strategy.evaluate(prob, u) if strategy else
                             get_gradient(route).evaluate(prob, u))
            except SimulationError as err:  # the simulation failing is no false alarm...
                assert u is nearby and not isinstance(err, GradientError)  # ...of the guard
                continue
            assert np.all(np.isfinite(found.gradient))
            if strategy:
                assert found.growth.growth < 1e-2 * GROWTH_BOUND, (name, found.growth)


def _per_control(prob, masses):
    """Each control's scale: a particle's mass for per-step forces, 1 otherwise."""
    if prob.size % masses.size == 0 and prob.size != masses.size:
        return np.tile(masses, prob.size // masses.size)
    return 1.0


def test_the_route_limits_and_the_warning_name_curved_penalty_contact_only():
    sphere = __import__("casadi_keyframe.models", fromlist=["Sphere"]).Sphere((0, 0, -2), 0.5)
    held = hanging_sheet(4, colliders=[sphere], collision="constraint")
    springs = hanging_sheet(4, colliders=[sphere], collision="penalty")
    assert Swapped().limits(hanging_sheet(4)) == []  # the ground: a plane
    assert Swapped().limits(held) == []
    assert Adjoint().limits(springs) == []
    assert "curved bodies (spheres)" in Swapped().limits(springs)[0]
    with pytest.warns(GradientRouteWarning, match="curved bodies \\(spheres\\).*swap-validity"):
        warn_route_limits(Swapped(), springs)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GradientRouteWarning)
        warn_route_limits(Swapped(), springs)  # once per model


def test_a_solve_records_each_iterations_growth(tmp_path):
    assert main(["solve", "flock_race", "--set", "agents=6", "--set", "steps=20",
                 "--maxiter", "5", "--out", str(tmp_path), "--quiet", "--no-animation",
                 "--no-viewer"]) in (0, 3)
    summary = json.loads((tmp_path / "summary.json").read_text())
    health = summary["gradient_health"]
    assert 1 < health["largest_growth"] < 1e3 and health["refused"] == 0
    assert summary["stages"][0]["gradient_growth"] == health["largest_growth"]
