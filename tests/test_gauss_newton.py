"""The searches on residuals: the Gauss-Newton trust region's CG path is the least-squares
solution cut at the radius; it and scipy's least_squares, as methods of solve, lower the
objective, never end above their start, keep bounds, stop at the time limit and on Ctrl-C,
refuse bad options and multiple shooting, and say how they ended."""
import time
from dataclasses import replace

import numpy as np
import pytest
from helpers import InterruptAfter

from casadi_keyframe import Adjoint, Smoothness, StateKeyframe, StepForces, load_problem, solve
from casadi_keyframe.models import ClothModel
from casadi_keyframe.optimize import CONVERGED, FAILED, INTERRUPTED, LIMIT
from casadi_keyframe.optimize.residual.descents import SteihaugPath, trust_region_small
from casadi_keyframe.scenes.cloths import cloth_problem


@pytest.fixture(scope="module")
def race():
    return load_problem("flock_race", agents=8, steps=40)


@pytest.mark.parametrize("rtol", [1e-12, 0.3])
def test_the_path_ends_at_the_least_squares_step_and_is_cut_at_the_radius(rtol):
    rng = np.random.default_rng(0)
    J = rng.standard_normal((30, 12)) * np.geomspace(1, 1e3, 12)  # a stiff model
    r = rng.standard_normal(30)
    path = SteihaugPath(J.dot, J.T.dot, r, J.T @ r, None, 50, rtol, plane=False)
    flat = SteihaugPath(J.dot, J.T.dot, r, J.T @ r, None, 50, rtol)
    best = np.linalg.lstsq(J, -r, rcond=None)[0]
    if rtol < 1e-6:
        assert np.allclose(path.step(None)[0], best, atol=1e-9)
    for radius in np.geomspace(1e-4, 0.9, 5) * np.linalg.norm(path.step(None)[0]):
        for way in (path, flat):
            p, model = way.step(radius)
            assert np.linalg.norm(p) <= radius * (1 + 1e-12)
            assert model == pytest.approx(0.5 * np.sum((r + J @ p) ** 2), rel=1e-10)
        assert np.linalg.norm(path.step(radius)[0]) == pytest.approx(radius, rel=1e-12)
        assert flat.step(radius)[1] <= path.step(radius)[1] * (1 + 1e-12)
    bounded = SteihaugPath(J.dot, J.T.dot, r, J.T @ r, 1e-3, 50, rtol, plane=False)
    assert np.allclose(bounded.step(1e-3)[0], path.step(1e-3)[0])  # the same path, stopped
    assert len(bounded.segments) <= len(path.segments)


def test_the_small_trust_region_solve_is_the_best_point_of_the_disc():
    rng = np.random.default_rng(3)
    angles = np.linspace(0, 2 * np.pi, 4001)
    for _ in range(20):
        A = rng.standard_normal((2, 2))
        B, c, radius = A @ A.T, rng.standard_normal(2), rng.uniform(0.05, 2)
        x = trust_region_small(B, c, radius)
        grid = [s * radius * np.array([np.cos(a), np.sin(a)]) for s in np.linspace(0, 1, 41)
                for a in angles[::20]]
        value = lambda y: 0.5 * y @ B @ y + c @ y  # noqa: E731
        assert np.linalg.norm(x) <= radius * (1 + 1e-9)
        assert value(x) <= min(value(y) for y in grid) + 1e-9


RESIDUAL_METHODS = ["gauss-newton", "least-squares"]
QUICK = {"gauss-newton": {}, "least-squares": {"lsmr_maxiter": 10}}  # tests stay fast


@pytest.mark.parametrize("method, tag", [("gauss-newton", "Gauss-Newton:"),
                                         ("least-squares", "least_squares:")])
def test_it_lowers_the_objective_and_reports_what_it_did(race, method, tag):
    start = race.objective(race.initial_controls())
    r = solve(race, method, maxiter=20, quiet=True, stop="method", options=QUICK[method])
    assert r.fun < 1e-2 * start and r.nit == len(r.history) > 0
    assert r.fun == pytest.approx(race.objective(r.x), rel=1e-12)
    assert tag in r.message and "Jacobian products" in r.message


@pytest.mark.parametrize("method", RESIDUAL_METHODS)
def test_bounds_hold_and_bind(method):
    prob = load_problem("flock_race", agents=8, steps=40)
    prob.controls.lower, prob.controls.upper = -0.5, 0.5
    r = solve(prob, method, maxiter=10, quiet=True, options=QUICK[method])
    assert np.abs(r.x).max() <= 0.5 + 1e-12 and np.abs(r.x).max() > 0.4


@pytest.mark.parametrize("method", RESIDUAL_METHODS)
def test_a_smooth_metric_searches_in_its_variables(method):
    model = ClothModel.grid(4, 4, plane="xz", pinned=[0, 3])
    free = np.flatnonzero(model.free_mask()[::3])
    x0 = model.rest_positions
    prob = cloth_problem(model=model, steps=10, dt=1 / 30, name="smooth",
                         objective=StateKeyframe(10, x=x0 + [0, 0.1, 0]) + Smoothness(1e-3),
                         controls=StepForces(free, smoothing=0.3, time_smoothing=0.1))
    start = prob.objective(prob.initial_controls())
    r = solve(prob, method, maxiter=5, quiet=True, stop="method")
    assert r.fun < start and r.fun == pytest.approx(prob.objective(r.x), rel=1e-12)


@pytest.mark.parametrize("method", RESIDUAL_METHODS)
def test_interrupt_keeps_the_best_point(race, method):
    r = solve(race, method, gradient=InterruptAfter(6), maxiter=100, quiet=True)
    assert r.status == INTERRUPTED and "interrupted" in r.message
    assert r.fun <= race.objective(race.initial_controls())


class Slow(Adjoint):
    def evaluate(self, problem, u):
        time.sleep(0.05)
        return super().evaluate(problem, u)


@pytest.mark.parametrize("method, limit", [("gauss-newton", {"maxfun": 4}),
                                           ("least-squares", {"max_nfev": 4})])
def test_the_time_limit_and_the_evaluation_limit_end_it_with_status_limit(race, method,
                                                                          limit):
    r = solve(race, method, gradient=Slow(), maxiter=500, quiet=True, time_limit=0.5)
    assert r.status == LIMIT and r.message.startswith("time limit reached (0.5 s)")
    r = solve(race, method, maxiter=500, quiet=True, stop="method", options=limit)
    assert r.status == LIMIT and "evaluation limit reached (4)" in r.message
    assert r.nfev <= 5  # the start and at most four trials


@pytest.mark.parametrize("options, message", [
    ({"inner_maxiters": 3}, "did you mean 'inner_maxiter'"),
    ({"inner_tol": 2.0}, "'inner_tol' must be a number in \\(0, 1\\)"),
    ({"radius": -1}, "'radius' must be a number > 0 or None"),
])
def test_bad_options_are_refused_by_name(race, options, message):
    with pytest.raises(ValueError, match=message):
        solve(race, "gauss-newton", options=options)


def test_a_jump_in_the_objective_collapses_the_region_and_fails_honestly(race):
    """An objective that jumps up at every move (as a cloth's does where a spring's law
    switches inside a step) is reported as a collapsed trust region, best point kept."""
    class Jumps(Adjoint):
        def evaluate(self, problem, u):
            found = super().evaluate(problem, u)
            jump = 1e6 if np.any(u != problem.initial_controls()) else 0.0
            return replace(found, value=found.value + jump)

    r = solve(race, "gauss-newton", gradient=Jumps(), maxiter=50, quiet=True,
              stop="method", options={"maxfun": 200})
    assert r.status == FAILED and "trust region collapsed" in r.message
    assert np.array_equal(r.x, race.initial_controls())


@pytest.mark.parametrize("method", RESIDUAL_METHODS)
def test_multiple_shooting_runs_on_the_merit_s_residuals(race, method):
    start = race.objective(race.initial_controls())
    r = solve(race, method, shooting={"segments": 2, "rounds": 1}, maxiter=3, quiet=True,
              stop="method")
    assert r.stages[0]["segments"] == 2 and r.stages[0]["nit"] > 0 and r.fun < start
