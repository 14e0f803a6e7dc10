"""Each paper problem solves at a reduced size and reaches its keyframes."""
import numpy as np
import pytest

from casadi_keyframe import load_problem, solve


def misses(result):
    return {m["term"]: m for m in result.breakdown["misses"]}


def test_flock_path_follows_the_path():
    prob = load_problem("flock_path", agents=30, steps=80)
    before = max(m["position_error"] for m in prob.breakdown(prob.initial_controls())["misses"])
    result = solve(prob, maxiter=100, quiet=True)
    errors = [m["position_error"] for m in result.breakdown["misses"]]
    assert before > 5.0
    assert max(errors) < 0.5 and np.median(errors) < 0.1  # path is 40 units long


def test_flock_race_runner_finishes_in_front():
    prob = load_problem("flock_race", agents=12, steps=80)
    (runner,) = prob.view.highlight
    x0 = prob.x0[:, 0]
    assert x0[runner] == x0.min()  # starts at the very back
    result = solve(prob, maxiter=200, quiet=True)
    x = result.trajectory.x[-1, :, 0]
    assert x[runner] - np.delete(x, runner).max() > 1.0  # ahead of every other agent
    com_errors = [m["position_error"] for t, m in misses(result).items() if t.startswith("Center")]
    assert max(com_errors) < 0.1


def test_flock_shapes_forms_square_then_cross():
    prob = load_problem("flock_shapes", agents=60, steps=100)
    start = [m["fraction_inside"] for m in prob.breakdown(prob.initial_controls())["misses"]]
    result = solve(prob, maxiter=150, quiet=True)
    inside = [m["fraction_inside"] for m in result.breakdown["misses"]]
    assert min(start) < 0.7
    assert min(inside) >= 0.95, inside


@pytest.mark.parametrize("dim", [3])
def test_three_dimensional_flock_solves(dim):
    prob = load_problem("flock_path", agents=20, steps=60, dim=dim)
    result = solve(prob, maxiter=80, quiet=True)
    assert max(m["position_error"] for m in result.breakdown["misses"]) < 0.5
