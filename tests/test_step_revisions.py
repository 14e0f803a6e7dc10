"""A step revised only to let particles go keeps its factor: the revision is solved on it,
bordered on the released directions (integrators/released.py), to a factorisation's
accuracy, and the derivative passes solve with the same bordered factor."""
import numpy as np
import pytest

from casadi_keyframe.integrators import linearized_backward_euler as lbe
from casadi_keyframe.integrators.released import ReleasedFactor

from helpers import assert_exact_routes, assert_forward_derivative
from test_contact_holds import drop_problem, peel_problem


def released(traj):
    return [r for r in traj.records if isinstance(r.factor, ReleasedFactor)]


@pytest.mark.parametrize("case", ["peel", "drop"])
def test_a_release_is_solved_on_the_step_s_factor_as_a_refactorisation_would(case, monkeypatch):
    prob, u = peel_problem() if case == "peel" else (drop_problem("guarded"), None)
    u = (u if u is not None else 0) + 0.01 * np.random.default_rng(0).standard_normal(prob.size)
    bordered = prob.simulate(u)
    assert released(bordered)  # some step let particles go on its factor
    monkeypatch.setattr(lbe, "RANK", 0)  # every revision factorised afresh
    again = prob.simulate(u)
    assert not released(again)
    assert [r.solves for r in again.records] == [r.solves for r in bordered.records]
    np.testing.assert_allclose(bordered.x, again.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(bordered.v, again.v, rtol=0, atol=1e-10)


def test_gradients_through_a_release_on_the_kept_factor_are_the_forward_pass_s():
    prob, lift = peel_problem()
    u = lift + 0.01 * np.random.default_rng(0).standard_normal(prob.size)
    assert released(prob.simulate(u))
    g, d = assert_exact_routes(prob, u)
    assert_forward_derivative(prob, u, g @ d, d)


def test_the_released_directions_are_the_dropped_members_held_ones():
    from casadi_keyframe.integrators.released import released_directions
    from casadi_keyframe.models.contact.held_set import HeldSet
    n = 4
    normals = np.array([[0, 0, 1.0], [0, 0.6, 0.8], [1.0, 0, 0]])
    old = HeldSet(np.array([0, 2, 3]), np.zeros(3, int), normals, np.zeros(3))
    new = HeldSet(np.array([0, 3]), np.zeros(2, int), normals[[0, 2]], np.zeros(2))
    Q = released_directions(old, new, n)
    assert Q.shape == (3 * n, 1)
    np.testing.assert_allclose(np.outer(Q[6:9, 0], Q[6:9, 0]), np.outer(normals[1], normals[1]),
                               atol=1e-15)
    moved = HeldSet(np.array([0, 3]), np.zeros(2, int), normals[[1, 2]], np.zeros(2))
    assert released_directions(old, moved, n) is None  # a kept member's normal changed


def test_a_release_on_a_kept_cholmod_factor_gives_the_exact_gradient():
    """The default solver keeps each step's CHOLMOD factor for the backward pass; a release
    bordered on it is kept the same way, and the derivative passes solve with it."""
    from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
    from casadi_keyframe.integrators import LinearizedBackwardEuler
    from casadi_keyframe.linear import cholmod_available
    if not cholmod_available():
        pytest.skip("CHOLMOD (cvxopt) is not installed")
    peel, lift = peel_problem()
    prob = ControlProblem(model=peel.model, integrator=LinearizedBackwardEuler("cholmod"),
                          x0=peel.x0, v0=peel.v0, steps=peel.steps, dt=peel.dt,
                          controls=StepForces(), objective=StateKeyframe(
                              peel.steps, x=peel.x0 + [0, 0, 0.02]) + Smoothness(1e-4))
    u = lift + 0.01 * np.random.default_rng(0).standard_normal(prob.size)
    assert released(prob.simulate(u))
    assert_exact_routes(prob, u)
