"""Every gradient route against every other (DESIGN.md section 5) on small flocks."""
import numpy as np
import pytest

from casadi_keyframe import FiniteDifference, InitialVelocity, StepForces

from helpers import small_flock


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def controls_for(prob, seed=0, scale=0.5):
    return scale * np.random.default_rng(seed).standard_normal(prob.size)


@pytest.mark.parametrize("dim", [2, 3])
def test_adjoint_matches_exact_reverse_mode(cutoff, dim):
    prob = small_flock(cutoff, dim=dim)
    u = controls_for(prob)
    fa, ga = prob.objective_and_gradient(u, "adjoint")
    fe, ge = prob.objective_and_gradient(u, "casadi")
    assert fa == pytest.approx(fe, rel=1e-12)
    assert rel(ga, ge) < 1e-8
    # every term contributes: the gradient has many non-zero entries
    assert np.count_nonzero(np.abs(ge) > 1e-10) > 0.5 * ge.size


@pytest.mark.parametrize("controls", [StepForces(agents=[0, 2, 5]), InitialVelocity(),
                                      InitialVelocity(agents=[1, 4])])
def test_adjoint_matches_exact_for_other_controls(controls):
    prob = small_flock(controls=controls)
    u = controls_for(prob, seed=1)
    assert rel(prob.objective_and_gradient(u, "adjoint")[1],
               prob.objective_and_gradient(u, "casadi")[1]) < 1e-8


def test_gradients_match_central_differences(cutoff):
    prob = small_flock(cutoff)
    u = controls_for(prob, seed=2)
    _, ga = prob.objective_and_gradient(u, "adjoint")
    _, ge = prob.objective_and_gradient(u, "casadi")
    fd = FiniteDifference(h=1e-5)
    rng = np.random.default_rng(3)
    for _ in range(4):
        d = rng.standard_normal(prob.size)
        d /= np.linalg.norm(d)
        slope = fd.directional(prob, u, d)
        scale = max(abs(slope), 1e-3 * np.linalg.norm(ge))
        assert abs(ga @ d - slope) < 1e-6 * scale
        assert abs(ge @ d - slope) < 1e-6 * scale


def test_full_finite_difference_gradient_on_a_tiny_problem():
    prob = small_flock(controls=InitialVelocity(), n=4, steps=12)
    u = controls_for(prob, seed=4)
    _, gfd = prob.objective_and_gradient(u, "fd")
    _, ga = prob.objective_and_gradient(u, "adjoint")
    assert rel(ga, gfd) < 1e-6


def test_taylor_remainder_is_second_order(cutoff):
    prob = small_flock(cutoff)
    u = controls_for(prob, seed=5)
    f0, g = prob.objective_and_gradient(u, "adjoint")
    h = np.random.default_rng(6).standard_normal(prob.size)
    h *= 0.5 / np.linalg.norm(h)
    eps = 0.5 ** np.arange(2, 9)
    remainder = np.array([abs(prob.objective(u + e * h) - f0 - e * (g @ h)) for e in eps])
    order = np.polyfit(np.log(eps), np.log(remainder), 1)[0]
    assert 1.8 < order < 2.2, f"Taylor remainder order {order:.2f}, remainders {remainder}"


def test_gradient_route_names_are_checked():
    prob = small_flock(n=5, steps=9)
    with pytest.raises(ValueError, match="unknown gradient"):
        prob.objective_and_gradient(prob.initial_controls(), "magic")
