"""The springs' rest band (``ClothParams(rest_band=...)``): the linearized step's stiffness
continuous across a spring's rest length, exact in every route, and the motion continuous in
the controls where the paper's step jumps."""
import numpy as np
import pytest
from helpers import assert_exact_routes

from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel, ClothParams
from casadi_keyframe.models.springs import REST_TOLERANCE, spring_kernels
from casadi_keyframe.scenes.sheets import swing_problem


def radial_stiffness(band, k_t, s, L=0.1, k_b=2e-5):
    """K's component along a spring of length ``s L`` (the step's stiffness kernel)."""
    K = spring_kernels(1e-6, band)["jac"]([s * L, 0, 0], [0, 0, 0], L, k_t, k_b, 0.02, 0.0)[0]
    return float(np.array(K).reshape(3, 3)[0, 0])


def test_the_band_makes_the_step_s_stiffness_continuous_at_rest_and_at_its_edge():
    below, above = 1 - 1e-7, 1 + 1e-7
    assert radial_stiffness(0.0, 500.0, below) < 1.0  # the paper's: the buckling slope
    assert radial_stiffness(0.0, 500.0, above) == pytest.approx(500.0)
    assert radial_stiffness(0.05, 500.0, below) == pytest.approx(500.0, rel=1e-5)
    edge = 1 - 0.05
    assert radial_stiffness(0.05, 500.0, edge + 1e-9) == pytest.approx(
        radial_stiffness(0.0, 500.0, edge), rel=1e-6)
    assert radial_stiffness(0.05, 500.0, 0.8) == radial_stiffness(0.0, 500.0, 0.8)
    bend = 24 * 2e-5 / 0.1 ** 3  # a bend spring's k_t is the buckling slope at rest: no lack
    for s in (0.9, 0.97, below):
        assert radial_stiffness(0.05, bend, s) == radial_stiffness(0.0, bend, s)


def test_rest_band_is_checked():
    with pytest.raises(ValueError, match="rest_band"):
        ClothParams(rest_band=1.0)
    with pytest.raises(ValueError, match="rest_band"):
        ClothParams(rest_band=-0.1)


def sheet(band):
    model = ClothModel.grid(4, 4, pinned=[0, 3], params=ClothParams(rest_band=band))
    prob = swing_problem(model, 12, 1 / 30, LinearizedBackwardEuler("direct"))
    return prob, 0.05 * np.random.default_rng(4).standard_normal(prob.size)


def test_the_banded_step_is_exact_in_every_route():
    prob, u = sheet(0.05)
    stretch = prob.model.springs.stretch(prob.simulate(u).x)
    assert np.mean((stretch < 1) & (stretch > 0.95)) > 0.2  # many springs inside the band
    assert_exact_routes(prob, u)


def crossing(prob, u, d):
    """The step along ``d`` from u where a spring first changes branch before the last
    frame, to round-off (bisection on the springs' branches)."""
    def branches(t):
        x = prob.simulate(u + t * d, records=False).x[:-1]
        return prob.model.springs.stretch(x) >= 1 - REST_TOLERANCE

    lo, hi, before = 0.0, 0.1, branches(0.0)
    assert (branches(hi) != before).any()
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if (branches(mid) != before).any() else (mid, hi)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("band", [0.0, 0.05])
def test_central_differences_across_a_spring_passing_rest(band):
    """The paper's step jumps where a spring's start-of-step length passes rest: a central
    difference straddling it grows like 1/h.  With the band the motion is continuous (the
    law's kink at rest stays: the slope is one side's), so the difference stays near it."""
    prob, u = sheet(band)
    d = np.random.default_rng(5).standard_normal(prob.size)
    d /= np.linalg.norm(d)
    t = crossing(prob, u, d)
    slope = prob.objective_and_gradient(u + t * d, "adjoint")[1] @ d
    errors = []
    for h in (1e-3, 1e-5, 1e-7):
        difference = (prob.objective(u + (t + h) * d) - prob.objective(u + (t - h) * d)) / (2 * h)
        errors.append(abs(difference - slope) / abs(slope))
    if band == 0:
        assert errors[-1] > 1e3 and errors[-1] > 50 * errors[0]
    else:
        assert max(errors) < 0.2
