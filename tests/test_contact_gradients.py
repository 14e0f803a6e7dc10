"""Every contact law's gradient is the derivative of the forward pass itself: the hand adjoint,
CasADi's reverse mode and the tangent pass against central differences of ``simulate``,
stable over three decades of h, through held bodies, the guard, the penalty springs,
self-contact, moving and mesh bodies, with friction sticking and sliding up to mu = 1.  CasADi
checks the algebra (it shares the model); the forward pass checks the model.  The whole grid
is ``benchmarks/contact_gradients.py`` (and the slow suite)."""
import numpy as np
import pytest

from casadi_keyframe.scenes.contact_gradients import LAWS, MOTIONS, contact_gradient_problem

from helpers import assert_forward_derivative

CASES = ([(law, "sliding", 0.0 if law == "penalty" else 0.6) for law in LAWS]
         + [("held", m, mu) for m in MOTIONS for mu in (0.3, 1.0)]
         + [("guarded", "sliding", 1.0), ("guarded", "sticking", 1.0),
            ("moving", "sticking", 1.0), ("mesh", "sticking", 1.0),
            ("self-contact", "sticking", 0.3)])


def check_routes(prob, u, seed=1):
    """The routes' slopes along a random unit direction against the forward pass; returns
    the adjoint's gradient."""
    d = np.random.default_rng(seed).standard_normal(prob.size)
    d /= np.linalg.norm(d)
    _, g = prob.objective_and_gradient(u, "adjoint")
    _, g_ref = prob.objective_and_gradient(u, "casadi")
    assert np.linalg.norm(g - g_ref) <= 1e-8 * np.linalg.norm(g_ref)  # the algebra
    assert prob.directional_derivative(u, d) == pytest.approx(g @ d, rel=1e-8)
    assert_forward_derivative(prob, u, g @ d, d)  # the model
    return g


@pytest.mark.parametrize("law, motion, mu", CASES)
def test_the_routes_are_the_forward_pass_s_derivative(law, motion, mu):
    prob, u = contact_gradient_problem(law, mu, motion)
    held = [r.held for r in prob.simulate(u).records if r.held is not None]
    if mu > 0:  # the scene does what it is named for
        stuck = sum(int(h.stick.sum()) for h in held)
        slid = sum(int((~h.stick).sum()) for h in held)
        assert (slid if motion == "sliding" else stuck) > 0, (stuck, slid)
    check_routes(prob, u)


@pytest.mark.slow
def test_the_whole_grid_of_laws_routes_and_coefficients():
    """Every law, sliding and sticking, mu = 0, 0.3, 0.6, 1: where the central differences
    are stable over three decades, every exact route meets them within 1e-6."""
    from casadi_keyframe.studies.forward_differences import stable_difference
    stable = 0
    for law in LAWS:
        for motion in MOTIONS:
            for mu in ((0.0,) if law == "penalty" else (0.0, 0.3, 0.6, 1.0)):
                prob, u = contact_gradient_problem(law, mu, motion)
                d = np.random.default_rng(1).standard_normal(prob.size)
                d /= np.linalg.norm(d)
                fd = stable_difference(prob, u, d)
                if fd.stable:
                    stable += 1
                    for route in ("adjoint", "casadi"):
                        g = prob.objective_and_gradient(u, route)[1]
                        assert fd.error(g @ d) <= 1e-6, (law, motion, mu, route)
                    assert fd.error(prob.directional_derivative(u, d)) <= 1e-6
    assert stable >= 40  # of 42 scenes (two have a decision within the larger steps)


def test_gradient_health_says_which_route_is_not_the_forward_pass_s_derivative():
    """With friction the exact routes are healthy and claim no limit; the paper's swapped
    adjoint, which leaves the sliding impulses' derivatives out, says so in its facts and
    in ``gradcheck``'s report."""
    from casadi_keyframe.adjoints import get_gradient
    from casadi_keyframe.studies.health_report import format_health, gradient_health
    prob, u = contact_gradient_problem("guarded", 0.6, "sliding")
    exact = gradient_health(prob, u, "adjoint", radius=False)
    assert exact.verdict == "healthy" and not exact.limits
    assert not get_gradient("casadi").limits(prob.model)
    swapped = gradient_health(prob, u, "swapped", radius=False)
    assert any("not the forward pass's derivative" in line for line in swapped.limits)
    assert "friction it is not the forward pass's derivative" in format_health(swapped)
    frictionless, _ = contact_gradient_problem("guarded", 0.0, "sliding")
    assert not get_gradient("swapped").limits(frictionless.model)
