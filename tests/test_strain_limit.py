"""The strain-limiting term: zero below its limit, its derivative against differences, the
adjoint route against CasADi's with the term in the objective, and a solve that keeps a
sheet's springs shorter than without it."""
import numpy as np
import pytest

from casadi_keyframe import StrainLimit, Trajectory, load_problem, solve
from casadi_keyframe.models import ClothModel


def swing(**term):
    prob = load_problem("cloth_shapes", rows=4, cols=4, steps=12)
    if term:
        prob = prob.with_objective(prob.objective_terms + StrainLimit(**term))
    return prob


def test_zero_below_the_limit_and_its_derivative():
    model = ClothModel.grid(4, 4)
    term = StrainLimit(limit=1.05, weight=10.0)
    term = term.bind(model, 3)
    rng = np.random.default_rng(0)
    x = model.rest_positions[None] + np.zeros((4, 1, 1))
    rest = Trajectory(x.copy(), np.zeros_like(x), 0.1)
    assert term.value(rest) == 0.0
    x[1:] += 0.08 * rng.standard_normal((3, model.n, 3))
    traj = Trajectory(x, np.zeros_like(x), 0.1)
    gx, gv = np.zeros_like(x), np.zeros_like(x)
    value = term.accumulate(traj, gx, gv)
    assert value == pytest.approx(term.value(traj)) and value > 0
    assert not gx[0].any() and not gv.any()  # frame 0 is given, not controlled
    d = rng.standard_normal(x.shape)
    d[0] = 0
    h = 1e-7
    plus = term.value(Trajectory(x + h * d, 0 * x, 0.1))
    minus = term.value(Trajectory(x - h * d, 0 * x, 0.1))
    assert np.sum(gx * d) == pytest.approx((plus - minus) / (2 * h), rel=1e-6)


def test_until_counts_the_frames_up_to_a_time_only():
    model = ClothModel.grid(4, 4)
    x = model.rest_positions[None] + 0.08 * np.random.default_rng(2).standard_normal((7, 16, 3))
    traj = Trajectory(x, np.zeros_like(x), 0.1)
    early, every = (StrainLimit(weight=10.0, until=0.3).bind(model, 6),
                    StrainLimit(weight=10.0).bind(model, 6))
    head = Trajectory(x[:4], np.zeros_like(x[:4]), 0.1)  # frames 0..3: t <= 0.3 s
    assert early.value(traj) == pytest.approx(every.value(head)) and early.value(traj) > 0
    gx, gv = np.zeros_like(x), np.zeros_like(x)
    early.accumulate(traj, gx, gv)
    assert gx[1:4].any() and not gx[4:].any()
    with pytest.raises(ValueError, match="until is a time"):
        StrainLimit(until=0)


@pytest.mark.parametrize("until", [None, 0.1])
def test_the_adjoint_route_equals_casadi_with_the_term(until):
    prob = swing(limit=1.0, weight=50.0, until=until)
    u = 0.05 * np.random.default_rng(1).standard_normal(prob.size)
    f_adj, g_adj = prob.objective_and_gradient(u, "adjoint")
    f_ad, g_ad = prob.objective_and_gradient(u, "casadi")
    assert f_adj == pytest.approx(f_ad, rel=1e-10)
    assert np.linalg.norm(g_adj - g_ad) < 1e-8 * np.linalg.norm(g_ad)
    plain = swing()
    assert f_adj > plain.objective(u)  # the springs are stretched past 1.0: it costs


def test_a_solve_with_the_term_keeps_springs_shorter():
    plain, limited = swing(), swing(limit=1.02, weight=1e4)
    a = solve(plain, maxiter=15, quiet=True)
    b = solve(limited, maxiter=15, quiet=True)
    assert b.breakdown["physical"]["max_stretch"] < a.breakdown["physical"]["max_stretch"]


def test_refusals():
    with pytest.raises(ValueError, match="limit >= 1"):
        StrainLimit(limit=0.9)
    flock = load_problem("flock_path", agents=4, steps=10)
    with pytest.raises(ValueError, match="needs a cloth"):
        flock.with_objective(flock.objective_terms + StrainLimit())
