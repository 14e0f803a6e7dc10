"""lower_effort: the keyframe held as a constraint while the control cost falls.

Its constraint Jacobian (adjoint sweeps seeded at the keyframe, stopped at the window) is
checked against central differences on a smooth sheet (the forward products and the
landing: tests/test_finish.py); the method itself on a small cape from the problem's
tracking guess, which no penalty solve improves (problems/cape_blend.py)."""
import numpy as np
import pytest
from test_augmented_lagrangian import swing

from casadi_keyframe import (CenterOfMassKeyframe, InitialVelocity, Smoothness, StateKeyframe,
                             backward, load_problem)
from casadi_keyframe.optimize.finish import KeyframeConstraint, control_hessian, lower_effort
from casadi_keyframe.optimize import CONVERGED


@pytest.mark.parametrize("first", [0, 6])
def test_the_constraint_jacobian_matches_central_differences(first):
    prob = swing()
    constraint = KeyframeConstraint(prob, first)
    rng = np.random.default_rng(first)
    u = 0.05 * rng.standard_normal(prob.size)
    mu = rng.standard_normal(constraint.size)
    g = constraint.linearize(prob.simulate(u)).vjp(mu)
    block = prob.size // prob.steps
    assert not g[:first * block].any()  # the steps before the window are not its to move
    for seed in (1, 2):
        d = np.random.default_rng(seed).standard_normal(prob.size)
        d[:first * block] = 0.0
        h = 1e-6
        fd = (mu @ constraint.residual(prob.simulate(u + h * d, records=False))
              - mu @ constraint.residual(prob.simulate(u - h * d, records=False))) / (2 * h)
        assert g @ d == pytest.approx(fd, rel=1e-6)


def test_a_stopped_backward_pass_gives_the_late_steps_their_full_gradients():
    prob = swing()
    traj = prob.simulate(0.05 * np.random.default_rng(0).standard_normal(prob.size))
    _, gx, gv = prob.state_cost(traj)
    full, _ = backward(prob.integrator, prob.model, traj, gx, gv)
    late, _ = backward(prob.integrator, prob.model, traj, gx, gv, stop=4)
    np.testing.assert_allclose(late[4:], full[4:], rtol=1e-12, atol=1e-15)
    assert not late[:4].any()
    with pytest.raises(ValueError, match="stop must be a frame"):
        backward(prob.integrator, prob.model, traj, gx, gv, stop=prob.steps + 1)


def test_the_control_hessian_is_the_smoothness_terms():
    prob = swing()
    Q = control_hessian(prob)
    u = np.random.default_rng(0).standard_normal(prob.size)
    value, grad = prob.control_cost(u)
    np.testing.assert_allclose(Q @ u, grad, rtol=1e-12)
    assert 0.5 * u @ (Q @ u) == pytest.approx(value, rel=1e-12)


def test_the_cape_keeps_its_landing_while_its_control_cost_falls():
    """8 x 6 cape over its default 1 s, held to 1 mm (its keyframe allows 6): a trial that
    leaves the landing is landed again, and one step lowers the control cost by a third."""
    prob = load_problem("cape_blend", rows=8, cols=6)
    start = prob.control_cost(prob.initial_controls())[0]
    result = lower_effort(prob, window=12, maxiter=1, position_tolerance=1e-3)
    assert result.status == CONVERGED and result.nit >= 1
    assert result.breakdown["control_cost"] < 0.8 * start
    misses = KeyframeConstraint(prob, 0).misses(result.trajectory)
    assert dict(misses)["x"] < 1e-3 and dict(misses)["v"] < 0.05, misses
    assert result.breakdown["physical"]["max_stretch"] < 1.3
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)


def test_a_start_that_misses_is_refused():
    prob = swing()  # zero forces: the sheet hangs 20 cm from its keyframe
    with pytest.raises(ValueError, match="it does not find one"):
        lower_effort(prob)


@pytest.mark.parametrize("change, message", [
    (lambda p: p.with_objective(CenterOfMassKeyframe(10, x=[0, 0.2, 0]) + Smoothness(1e-2)),
     "StateKeyframe goals only"),
    (lambda p: p.with_controls(InitialVelocity()), "per-step forces"),
    (lambda p: p.with_objective(StateKeyframe(10, x=p.x0)), "singular on the window"),
])
def test_what_it_cannot_hold_is_refused_by_name(change, message):
    with pytest.raises(ValueError, match=message):
        lower_effort(change(swing()))


@pytest.mark.parametrize("kwargs, message", [
    ({"window": 0}, "window must be"), ({"position_tolerance": -1.0}, "position_tolerance"),
])
def test_bad_options_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        lower_effort(swing(), **kwargs)
