"""Full backward Euler: Newton converges to the implicit step, its adjoint is exact (against
CasADi's differentiated rootfinder and against finite differences), and the linearized step
differs from it by O(dt^3) per step."""
import numpy as np
import pytest

from casadi_keyframe import CenterOfMassKeyframe, ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.adjoints import FiniteDifference
from casadi_keyframe.integrators import BackwardEuler, LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models import Attachment
from casadi_keyframe.models.contact.colliders import Contact, Plane, Sphere
from casadi_keyframe.simulate import simulate


def scene_problem(integrator, steps=10, dt=1 / 30, collision="penalty"):
    """4 x 4 sheet: a pin, an attachment on a path, a sphere and the ground in contact (the
    paper's penalty contact: full backward Euler steps that)."""
    model = ClothModel.grid(4, 4, pinned=[3], colliders=[Sphere((0.5, 0.15, -0.8), 0.2),
                                                         Plane((0, 0, -1.005))],
                            collision=collision,
                            self_contact=Contact(200.0, 0.5, 0.2, 0.05),
                            attachments=[Attachment([0], lambda t: np.array([[0.2 * t, 0, 0]]))])
    x0 = model.rest_positions
    obj = (StateKeyframe(steps, x=x0 + [0.0, 0.2, 0.05], v=0 * x0)
           + CenterOfMassKeyframe(steps // 2, x=x0.mean(0) + [0, 0.1, 0]) + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=integrator, x0=x0, v0=np.zeros_like(x0),
                          steps=steps, dt=dt, controls=StepForces(), objective=obj)


@pytest.mark.parametrize("solver, most", [("direct", 10), ("cg", 40)])
def test_newton_solves_the_implicit_step(solver, most):
    prob = scene_problem(BackwardEuler(solver))
    u = 0.05 * np.random.default_rng(0).standard_normal(prob.size)
    traj = prob.simulate(u)
    model, dt, ext = prob.model, prob.dt, prob.controls.external(u)
    contact = [np.abs(model.forces(x, v, n * dt, role="contact")).max() for n, (x, v) in
               enumerate(zip(traj.x, traj.v))]
    assert max(contact) > 0.1  # the scene really touches something
    for n in range(prob.steps):
        x1, v1 = traj.x[n + 1], traj.v[n + 1]
        residual = (model.masses[:, None] * (v1 - traj.v[n])
                    - dt * (model.forces(x1, v1, (n + 1) * dt) + ext[n]))
        free = model.free_mask().reshape(-1, 3)
        assert np.abs(residual[free]).max() < 1e-9
        np.testing.assert_allclose(x1, traj.x[n] + dt * v1, atol=1e-14)
    np.testing.assert_allclose(traj.x[-1, 0], [0.2 * prob.steps * dt, 0, 0], atol=1e-12)
    assert np.all(traj.x[:, 3] == traj.x[0, 3])
    assert max(r.iterations for r in traj.records) < most
    assert all(info.residual < 1e-6 for r in traj.records for info in r.solves)


@pytest.mark.parametrize("solver", ["cg", "direct"])
def test_backward_euler_adjoint_is_exact(solver):
    prob = scene_problem(BackwardEuler(solver))
    u = 0.05 * np.random.default_rng(1).standard_normal(prob.size)
    f_hand, g_hand = prob.objective_and_gradient(u, "adjoint")
    f_ad, g_ad = prob.objective_and_gradient(u, "casadi")
    assert abs(f_hand - f_ad) < 1e-9 * abs(f_ad)
    assert np.linalg.norm(g_hand - g_ad) < 1e-7 * np.linalg.norm(g_ad)
    rng = np.random.default_rng(2)
    for _ in range(2):
        d = rng.standard_normal(prob.size)
        d /= np.linalg.norm(d)
        slope = FiniteDifference(1e-6).directional(prob, u, d)
        assert abs(g_hand @ d - slope) <= 1e-6 * max(abs(slope), 1e-3 * np.linalg.norm(g_hand))


def test_one_step_difference_to_the_linearized_step_is_third_order():
    model = ClothModel.grid(5, 5, pinned=[0, 4])
    rng = np.random.default_rng(3)
    x0 = model.rest_positions + 0.02 * rng.standard_normal((model.n, 3))
    v0 = 0.3 * rng.standard_normal((model.n, 3))
    dts = np.array([1 / 60, 1 / 120, 1 / 240, 1 / 480])
    gaps = []
    for dt in dts:
        e = np.zeros((1, model.n, 3))
        full = simulate(BackwardEuler("direct"), model, x0, v0, e, dt)
        lin = simulate(LinearizedBackwardEuler("direct"), model, x0, v0, e, dt)
        gaps.append(np.abs(full.x[1] - lin.x[1]).max())
    order = np.polyfit(np.log(dts), np.log(gaps), 1)[0]
    assert 2.6 < order < 3.4, (order, gaps)


def test_contact_held_by_the_step_is_refused_with_the_way_out():
    with pytest.raises(ValueError, match="collision='penalty'"):
        scene_problem(BackwardEuler(), collision="guarded").simulate()
    assert scene_problem(LinearizedBackwardEuler(), collision="guarded").simulate().steps == 10


def test_bad_newton_options_are_refused():
    with pytest.raises(ValueError, match="newton_tol"):
        BackwardEuler(newton_tol=0)
    with pytest.raises(ValueError, match="solver must be"):
        BackwardEuler("lu")
