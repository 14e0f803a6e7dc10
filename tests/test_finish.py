"""The keyframes held as a constraint on a window of late steps: the window's Jacobian
products (exact against central differences and each other), the landing step, and
``solve(..., finish=...)``: a search that stops short lands, the story stays one."""
import json

import numpy as np
import pytest
from test_augmented_lagrangian import swing

from casadi_keyframe import InitialVelocity, Smoothness, StateKeyframe, load_problem
from casadi_keyframe.optimize import CONVERGED, solve
from casadi_keyframe.optimize.constrained import land, lower_effort
from casadi_keyframe.optimize.finish import finish_options
from casadi_keyframe.optimize.window_step import KeyframeConstraint
from casadi_keyframe.simulate import tangent


def tight(prob, tolerance=1e-3):
    """``prob`` (the swing) with its keyframe's tolerance ``tolerance``: its penalty search
    stops millimetres off."""
    t = prob.objective_terms.state_terms[0]
    return prob.with_objective(StateKeyframe(t.frame, x=t.x, position_weight=20.0,
                                             agents=t.agents, tolerance=tolerance)
                               + Smoothness(2e-2))


@pytest.mark.parametrize("first", [0, 4])
def test_the_window_products_are_exact_and_transposes(first):
    prob = swing()
    constraint = KeyframeConstraint(prob, first)
    rng = np.random.default_rng(first)
    u = 0.05 * rng.standard_normal(prob.size)
    traj = prob.simulate(u)
    block = prob.size // prob.steps
    d = rng.standard_normal(prob.size)
    d[:first * block] = 0.0
    w = rng.standard_normal(constraint.size)
    Jd, JTw = constraint.jvp(traj, d), constraint.vjp(traj, w)
    assert w @ Jd == pytest.approx(d @ JTw, rel=1e-10)
    h = 1e-6
    fd = (constraint.residual(prob.simulate(u + h * d, records=False))
          - constraint.residual(prob.simulate(u - h * d, records=False))) / (2 * h)
    np.testing.assert_allclose(Jd, fd, rtol=1e-5, atol=1e-8 * np.abs(fd).max())


def test_a_tangent_from_a_later_frame_is_the_whole_tangent_of_a_late_change():
    prob = swing()
    traj = prob.simulate(0.05 * np.random.default_rng(0).standard_normal(prob.size))
    forces = np.random.default_rng(1).standard_normal(prob.external.shape)
    forces[:4] = 0.0
    zero = np.zeros_like(prob.x0)
    whole = tangent(prob.integrator, prob.model, traj, zero, zero, forces)
    late = tangent(prob.integrator, prob.model, traj, zero, zero, forces, start=4)
    for a, b in zip(whole, late):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="start must be a frame"):
        tangent(prob.integrator, prob.model, traj, zero, zero, forces, start=prob.steps + 1)


def test_land_puts_a_missed_keyframe_within_its_tolerance():
    prob = tight(swing())
    short = solve(prob, maxiter=50, quiet=True)
    assert short.status != CONVERGED  # the penalty search stops millimetres off
    result = land(prob, u0=short.x)
    assert result.status == CONVERGED and result.nit >= 1, result.message
    assert result.breakdown["misses"][0]["rms_position_error"] <= 1e-3
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)


def test_solve_finishes_by_landing_and_tells_one_story():
    prob = tight(swing())
    result = solve(prob, maxiter=50, quiet=True, finish="land")
    assert result.status == CONVERGED, result.message
    assert "finish (land)" in result.message
    assert [s["stage"] for s in result.stages] == [0, 1]
    assert result.nit == sum(s["nit"] for s in result.stages)
    assert result.history[-1]["objective"] == pytest.approx(result.fun, rel=1e-9)
    assert result.stages[-1]["fun"] == pytest.approx(result.fun, rel=1e-9)
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)


def test_lower_effort_keeping_the_objective_never_raises_it():
    prob = tight(swing(), tolerance=5e-3)
    start = solve(prob, maxiter=50, quiet=True, finish="land").x
    result = lower_effort(prob, u0=start, maxiter=3, keep_objective=True)
    assert result.fun <= prob.objective(start) + 1e-15
    assert prob.control_cost(result.x)[0] <= prob.control_cost(start)[0]


def test_the_finish_refuses_what_it_cannot_hold_before_searching():
    with pytest.raises(ValueError, match="StateKeyframe terms only"):
        solve(load_problem("flock_path", agents=6, steps=20), finish="land", maxiter=1)
    with pytest.raises(ValueError, match="per-step forces"):
        solve(swing().with_controls(InitialVelocity()), finish="effort", maxiter=1)


@pytest.mark.parametrize("finish, message", [
    ("polish", "kind must be one of"), ({"kind": "land", "steps": 3}, "unknown option"),
    ("effort,window", "expected KIND,window=N"), ("land,maxiter=0", "maxiter must be"),
    ({"window": 0}, "window must be"), (3, "finish must be one of"),
])
def test_bad_finish_options_are_refused_by_name(finish, message):
    with pytest.raises(ValueError, match=message):
        finish_options(finish)


def test_the_command_line_finishes_the_cape_with_less_effort(tmp_path):
    """A 4 x 3 cape from its tracking guess (on its keyframe): the effort finish runs,
    is recorded as a stage, and the result is never worse than the start."""
    from casadi_keyframe.cli import main

    out = tmp_path / "cape"
    code = main(["solve", "cape_blend", "--set", "rows=4", "--set", "cols=3", "--finish",
                 "effort,maxiter=1", "--quiet", "--no-animation", "--no-viewer", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0, summary["message"]
    assert "finish (lower_effort)" in summary["message"]
    assert [s["nit"] for s in summary["stages"]] == [0, 1]
    assert summary["fun"] == pytest.approx(summary["stages"][-1]["fun"], rel=1e-9)
    assert summary["fun"] <= summary["stages"][0]["start_objective"] * (1 + 1e-12)


def test_finish_and_rounds_are_refused_together(capsys):
    from casadi_keyframe.cli import main

    assert main(["solve", "flock_path", "--rounds", "2", "--finish", "land"]) != 0
    assert "--finish holds the keyframes after one search" in capsys.readouterr().err
