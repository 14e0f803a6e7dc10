"""Optimizers: L-BFGS-B and IPOPT agree, bounds hold, Ctrl-C keeps the best result."""
import numpy as np
import pytest

from casadi_keyframe import Adjoint, SimulationError, load_problem, solve

from conftest import InterruptAfter


@pytest.fixture(scope="module")
def race():
    return load_problem("flock_race", agents=8, steps=40)


def test_lbfgsb_and_ipopt_reach_the_same_objective(race):
    a = solve(race, "lbfgsb", maxiter=150, quiet=True)
    b = solve(race, "ipopt", maxiter=150, quiet=True)
    passive = race.objective(race.initial_controls())
    assert a.fun < 1e-2 * passive and b.fun < 1e-2 * passive
    assert b.fun == pytest.approx(a.fun, rel=0.05)
    for r in (a, b):
        assert r.nit == len(r.history) and r.nit > 0
        assert {"objective", "keyframe_error", "control_norm", "seconds"} <= set(r.history[0])
        assert r.fun == pytest.approx(race.objective(r.x), rel=1e-12)
        assert r.trajectory.x.shape == (41, 8, 2)


@pytest.mark.parametrize("method", ["lbfgsb", "ipopt"])
def test_bounds_are_respected(race, method):
    prob = load_problem("flock_race", agents=8, steps=40)
    prob.controls.lower, prob.controls.upper = -0.5, 0.5
    r = solve(prob, method, maxiter=50, quiet=True)
    assert np.abs(r.x).max() <= 0.5 + 1e-9
    assert np.abs(r.x).max() > 0.4  # the bound is active: the problem wants more force


@pytest.mark.parametrize("method", ["lbfgsb", "ipopt"])
def test_interrupt_returns_and_saves_the_best_result(race, method, tmp_path):
    ckpt = tmp_path / "best.npz"
    r = solve(race, method, gradient=InterruptAfter(12), maxiter=500, quiet=True,
              checkpoint=ckpt)
    assert "interrupted" in r.message and not r.success
    saved = np.load(ckpt)
    assert saved["fun"] <= race.objective(race.initial_controls())
    assert r.fun <= float(saved["fun"]) + 1e-12
    assert r.fun == pytest.approx(race.objective(r.x), rel=1e-12)


def test_failed_simulations_during_the_search_are_counted_not_returned(race):
    class Fails(Adjoint):
        count = 0

        def __call__(self, problem, u):
            Fails.count += 1
            if Fails.count in (3, 4):
                raise SimulationError("blew up", 1)
            return super().__call__(problem, u)

    r = solve(race, gradient=Fails(), maxiter=30, quiet=True)
    assert r.timings["failed_simulations"] >= 1 and np.isfinite(r.fun)
    # and the search goes on past them (an infinite objective made L-BFGS-B give up)
    assert r.nit > 10 and r.fun < 0.2 * race.objective(race.initial_controls())


def test_unknown_method_is_refused(race):
    with pytest.raises(ValueError, match="unknown method"):
        solve(race, "newton")
