"""The control cost weighed per particle (``Smoothness(weights=...)``): in accelerations it
is the cost of ``u / m``, every route of the term (its CasADi expression, its residual form
and their derivatives) agrees, and a weight list of the wrong length is refused by name."""
import numpy as np
import pytest

from casadi_keyframe import ControlProblem, InitialVelocity, Smoothness, StepForces, load_problem
from casadi_keyframe.optimize.finish.constraint import control_hessian
from helpers import small_flock

ALPHA, TEMPORAL = 0.01, 0.003


def flock_with(term, controls=None):
    """The small flock (unequal masses) with ``term`` as its only control term."""
    base = small_flock(controls=controls)
    states = list(base.objective_terms.state_terms)
    return ControlProblem(model=base.model, integrator=base.integrator, x0=base.x0,
                          v0=base.v0, steps=base.steps, dt=base.dt,
                          controls=controls or StepForces(),
                          objective=sum(states[1:], states[0] + term),
                          external=base.external, name="weighted_flock")


def test_the_cost_in_accelerations_is_the_cost_of_each_force_over_its_mass():
    masses = small_flock().model.masses
    prob = flock_with(Smoothness.in_accelerations(ALPHA, masses, temporal=TEMPORAL))
    u = np.random.default_rng(1).standard_normal(prob.size)
    a = u.reshape(prob.steps, masses.size, -1) / masses[None, :, None]
    scale = masses.mean() ** 2
    expected = (0.5 * ALPHA * prob.dt * scale * np.sum(a ** 2)
                + 0.5 * TEMPORAL / prob.dt * scale * np.sum(np.diff(a, axis=0) ** 2))
    value, gradient = prob.control_cost(u)
    assert value == pytest.approx(expected, rel=1e-12)
    Q = control_hessian(prob)
    np.testing.assert_allclose(Q @ u, gradient, rtol=1e-12, atol=1e-15)
    # a light particle's force costs more than a heavy one's, the mean mass's as unweighted
    unweighted = flock_with(Smoothness(ALPHA, temporal=TEMPORAL))
    light, heavy = np.argmin(masses), np.argmax(masses)
    one = np.zeros((prob.steps, masses.size, prob.model.dim))
    one[3, light, 0] = 1.0
    other = np.zeros_like(one)
    other[3, heavy, 0] = 1.0
    assert prob.control_cost(one.ravel())[0] > unweighted.control_cost(one.ravel())[0]
    assert prob.control_cost(other.ravel())[0] < unweighted.control_cost(other.ravel())[0]


@pytest.mark.parametrize("controls", [StepForces(), InitialVelocity()], ids=["forces", "velocity"])
def test_the_weighed_residual_form_is_the_expression_and_its_products_are_transposes(controls):
    masses = small_flock().model.masses
    prob = flock_with(Smoothness.in_accelerations(ALPHA, masses, temporal=TEMPORAL), controls)
    term = prob.objective_terms.control_terms[0]
    rng = np.random.default_rng(2)
    u, du = rng.standard_normal(prob.size), rng.standard_normal(prob.size)
    r = term.residual(u, prob.controls, prob.dt)
    assert 0.5 * r @ r == pytest.approx(prob.control_cost(u)[0], rel=1e-12)
    w = rng.standard_normal(r.size)
    jvp = term.residual_jvp(du, prob.controls, prob.dt)
    vjp = term.residual_vjp(w, prob.controls, prob.dt)
    assert w @ jvp == pytest.approx(vjp @ du, rel=1e-12)
    np.testing.assert_allclose(term.residual_vjp(r, prob.controls, prob.dt),
                               prob.control_cost(u)[1], rtol=1e-12, atol=1e-15)


def test_equal_masses_weigh_nothing():
    masses = np.full(small_flock().model.masses.size, 0.7)
    weighted = flock_with(Smoothness.in_accelerations(ALPHA, masses, temporal=TEMPORAL))
    plain = flock_with(Smoothness(ALPHA, temporal=TEMPORAL))
    u = np.random.default_rng(3).standard_normal(plain.size)
    assert weighted.control_cost(u)[0] == pytest.approx(plain.control_cost(u)[0], rel=1e-14)


def test_weights_of_another_count_or_sign_are_refused_by_name():
    n = small_flock().model.masses.size
    with pytest.raises(ValueError, match="one per controlled particle"):
        flock_with(Smoothness(ALPHA, weights=np.ones(n + 1)))
    with pytest.raises(ValueError, match="positive"):
        Smoothness(ALPHA, weights=[1.0, -1.0])
    with pytest.raises(ValueError, match="masses"):
        Smoothness.in_accelerations(ALPHA, [1.0, 0.0])
    with pytest.raises(ValueError, match="alpha and temporal"):
        Smoothness(-1.0)


def test_mesh_keyframes_measures_its_effort_in_accelerations_unless_told_force():
    accel = load_problem("mesh_keyframes", guess="none")
    force = load_problem("mesh_keyframes", guess="none", effort="force")
    masses = accel.model.masses[accel.controls.idx]
    assert masses.max() > 3 * masses.min()  # a mesh's corners are light
    u = np.random.default_rng(4).standard_normal(accel.size)
    a = u.reshape(accel.steps, masses.size, 3) / masses[None, :, None]
    assert accel.control_cost(u)[0] == pytest.approx(
        0.5 * 1e-4 * accel.dt * masses.mean() ** 2 * np.sum(a ** 2), rel=1e-12)
    assert force.control_cost(u)[0] == pytest.approx(0.5 * 1e-4 * force.dt * u @ u, rel=1e-12)
    velocity = load_problem("mesh_keyframes", guess="none", control="velocity")
    assert velocity.objective_terms.control_terms[0].weights is None  # velocities: kinematic
