"""Objective terms and shapes: values against plain numpy, and bad input."""
import numpy as np
import pytest

from casadi_keyframe import (CenterOfMassKeyframe, ControlProblem, Smoothness,
                             StateKeyframe, StepForces, load_problem)
from casadi_keyframe.integrators import SymplecticEuler
from casadi_keyframe.models import FlockModel
from casadi_keyframe.shapes import Box, Disc, cross, square

from helpers import small_flock


def test_shape_signed_distances():
    c = cross((0, 0), 4, 1)
    pts = [[0, 0], [1.5, 0], [1.5, 1.5], [3, 0], [0.4, 1.9]]
    np.testing.assert_allclose(c.signed_distance(pts), [-np.sqrt(0.5), -0.5, 1.0, 1.0, -0.1],
                               atol=1e-6)
    assert c.area() == pytest.approx(7.0)
    np.testing.assert_allclose(Box((0, 0), (2, 1)).signed_distance([[0, 0], [2, 0], [3, 1.5]]),
                               [-0.5, 1.0, np.hypot(2, 1)], atol=1e-5)
    np.testing.assert_allclose(Disc((1, 1), 1).signed_distance([[1, 1], [3, 1]]), [-1, 1], atol=1e-5)
    assert square((0, 0), 2).contains([[0.9, 0.9], [1.1, 0]]).tolist() == [True, False]


def test_polygon_handles_a_non_convex_shape_like_its_rasterisation():
    c = cross((2, 3), 6, 2)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-2, 6, (4000, 2))
    inside = c.contains(pts)
    local = np.abs(pts - [2, 3])
    truth = ((local[:, 0] <= 1) & (local[:, 1] <= 3)) | ((local[:, 1] <= 1) & (local[:, 0] <= 3))
    assert np.mean(inside == truth) > 0.999


def _frame_state(prob, u, n):
    traj = prob.simulate(u)
    return traj, traj.x[n], traj.v[n]


def test_term_values_match_numpy():
    prob = small_flock()
    u = 0.3 * np.random.default_rng(0).standard_normal(prob.size)
    terms = prob.objective_terms.state_terms
    traj = prob.simulate(u)
    state = terms[0]
    x, v = traj.x[state.frame], traj.v[state.frame]
    expect = 0.5 * (np.sum((x - state.x) ** 2) + 0.3 * np.sum(v ** 2))
    assert state.value(traj) == pytest.approx(expect, rel=1e-12)
    com = terms[2]
    m = prob.model.masses
    cx = m @ traj.x[com.frame] / m.sum()
    cv = m @ traj.v[com.frame] / m.sum()
    assert com.value(traj) == pytest.approx(
        0.5 * (np.sum((cx - 3) ** 2) + np.sum((cv - [1, 0]) ** 2)), rel=1e-12)
    region = terms[3]
    sd = region.shape.signed_distance(traj.x[region.frame])
    assert region.value(traj) == pytest.approx(
        0.5 * 2.0 * np.sum(np.maximum(sd + 0.1, 0) ** 2), rel=1e-9)
    steps_u = u.reshape(prob.steps, -1)
    smooth = 0.5 * 0.01 * prob.dt * np.sum(u ** 2) + 0.5 * 0.01 / prob.dt * np.sum(np.diff(steps_u, axis=0) ** 2)
    assert prob.control_cost(u)[0] == pytest.approx(smooth, rel=1e-12)


def test_terms_add_up():
    a, b, c = (StateKeyframe(1, x=np.zeros((2, 2))), CenterOfMassKeyframe(2, x=[0, 0]),
               Smoothness(1.0))
    obj = a + b + c
    assert obj.terms == [a, b, c] and obj.state_terms == [a, b] and obj.control_terms == [c]
    assert (sum([a, b])).terms == [a, b]


def flock(n=3, **kw):
    base = dict(model=FlockModel(np.ones(n)), integrator=SymplecticEuler(),
                x0=np.zeros((n, 2)) + np.arange(n)[:, None], v0=np.zeros((n, 2)), steps=10,
                dt=0.1, controls=StepForces(), objective=CenterOfMassKeyframe(10, x=[1, 1]))
    base.update(kw)
    return ControlProblem(**base)


@pytest.mark.parametrize("kw, match", [
    (dict(dt=0.0), "dt must be positive"),
    (dict(dt=-1.0), "dt must be positive"),
    (dict(steps=0), "steps must be a positive integer"),
    (dict(x0=np.zeros((2, 2))), r"initial positions x0 must have shape \(3, 2\)"),
    (dict(v0=np.full((3, 2), np.nan)), "NaN"),
    (dict(objective=CenterOfMassKeyframe(11, x=[0, 0])), "frame 11 is outside 0..10"),
    (dict(objective=StateKeyframe(5, x=np.zeros((4, 2)))), "target must have shape"),
    (dict(objective=StateKeyframe(5, x=np.zeros((3, 2)), agents=[7])), "out of range"),
    (dict(objective=Smoothness(1.0)), "no keyframe term"),
    (dict(controls=StepForces(lower=1.0)), "contain zero"),
    (dict(external=np.zeros((3, 3, 2))), "external forces must have shape"),
])
def test_bad_problems_get_clear_errors(kw, match):
    with pytest.raises(ValueError, match=match):
        flock(**kw)


def test_bad_controls_and_overrides_get_clear_errors():
    prob = flock()
    with pytest.raises(ValueError, match="flat vector of 60 real numbers"):
        prob.objective(np.zeros(7))
    with pytest.raises(ValueError, match="NaN"):
        prob.objective(np.full(60, np.nan))
    with pytest.raises(ValueError, match=r"unknown override agnets \(did you mean agents\?\)"
                                         r".*valid names"):
        load_problem("flock_path", agnets=10)
    with pytest.raises(FileNotFoundError, match="known problems"):
        load_problem("no_such_problem")


def test_blow_up_is_reported_not_returned():
    from casadi_keyframe import SimulationError
    from casadi_keyframe.models import FlockParams
    prob = flock(model=FlockModel(np.ones(3), params=FlockParams(drag=100.0)),  # dt*drag = 10
                 v0=np.ones((3, 2)))
    with pytest.raises(SimulationError, match="blew up|NaN") as err:
        prob.simulate()
    assert 0 < err.value.step <= 10
