"""Linearized backward Euler: CG equals direct, exact route against differences, and the
swapped adjoint (exact for linear forces, a good descent direction for cloth)."""
import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sp

from casadi_keyframe import CenterOfMassKeyframe, ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.adjoints import FiniteDifference
from casadi_keyframe.models.base import ForceJacobians, Model
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.scenes.sheets import hanging_sheet, swing_problem
from casadi_keyframe.studies.accuracy import relative_error_and_cosine
from casadi_keyframe.state import State


def cloth_problem(solver="cg", steps=12, dt=1 / 30):
    return swing_problem(hanging_sheet(4, ground=False), steps, dt,
                         LinearizedBackwardEuler(solver), name="tiny_cloth")


def test_cg_and_direct_simulations_agree():
    u = 0.05 * np.random.default_rng(0).standard_normal(cloth_problem().size)
    a = cloth_problem("cg").simulate(u)
    b = cloth_problem("direct").simulate(u)
    np.testing.assert_allclose(a.x, b.x, atol=1e-9)
    assert np.all(a.x[:, [0, 3]] == a.x[0, [0, 3]])  # pinned particles stay put


def test_exact_route_matches_central_differences_and_taylor():
    prob = cloth_problem()
    u = 0.05 * np.random.default_rng(4).standard_normal(prob.size)
    # the Choi-Ko law's stiffness jumps at rest length: differences straddling a spring's
    # passage through it measure that jump, not the slope, so none passes within 1e-5 here
    s, x = prob.model.springs, prob.simulate(u).x[1:]
    length = np.linalg.norm(x[:, s.j] - x[:, s.i], axis=2)
    assert np.abs(length / s.rest - 1).min() > 1e-5
    f0, g = prob.objective_and_gradient(u, "casadi")
    rng = np.random.default_rng(2)
    for _ in range(3):
        d = rng.standard_normal(prob.size)
        d /= np.linalg.norm(d)
        slope = FiniteDifference(1e-5).directional(prob, u, d)  # CG's noise floor: h >= 1e-5
        assert abs(g @ d - slope) <= 1e-6 * max(abs(slope), 1e-3 * np.linalg.norm(g))
    h = 0.1 * rng.standard_normal(prob.size)
    eps = 0.5 ** np.arange(1, 7)
    rem = [abs(prob.objective(u + e * h) - f0 - e * (g @ h)) for e in eps]
    assert 1.8 < np.polyfit(np.log(eps), np.log(rem), 1)[0] < 2.2


def test_swapped_adjoint_is_a_descent_direction_close_to_exact():
    prob = cloth_problem()
    u = 0.05 * np.random.default_rng(3).standard_normal(prob.size)
    f0, ga = prob.objective_and_gradient(u, "swapped")
    _, ge = prob.objective_and_gradient(u, "casadi")
    assert relative_error_and_cosine(ga, ge)[1] > 0.9
    assert prob.objective(u - 1e-3 * ga / np.linalg.norm(ga)) < f0


class LinearModel(Model, ForceJacobians):
    """f = K x + D v with constant symmetric K, D: linearized and full backward Euler coincide.
    A model with sparse Jacobians only (no blocks): the step takes the general route."""

    def __init__(self, n, pinned=()):
        rng = np.random.default_rng(0)
        self.n, self.dim, self.masses = n, 3, np.linspace(1, 2, n)
        B, C = rng.standard_normal((2, 3 * n, 3 * n))
        self.K = -(B @ B.T) / n - np.eye(3 * n)
        self.D = -(C @ C.T) / (10 * n)
        self.pinned = np.asarray(pinned, int)

    def free_mask(self):
        free = np.ones((self.n, 3), bool)
        free[self.pinned] = False
        return free.ravel()

    def forces(self, x, v, t=0.0, interactions=None):
        return (self.K @ x.ravel() + self.D @ v.ravel()).reshape(self.n, 3)

    def jacobians(self, x, v, t=0.0, with_df_dx=False, interactions=None):
        K, D = sp.csc_matrix(self.K), sp.csc_matrix(self.D)
        return (K, D, K) if with_df_dx else (K, D)

    def linearization_vjp(self, x, v, t, lam, w, q, dt, interactions=None):
        """Linear forces: ``lam . (dt f + ...)`` has the gradients ``dt K^T lam``, ``dt D^T lam``."""
        lam = lam.ravel()
        return (dt * (self.K.T @ lam)).reshape(self.n, 3), (dt * (self.D.T @ lam)).reshape(self.n, 3)

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, interactions=None):
        return (dt * (self.K @ dx.ravel() + self.D @ dv.ravel())).reshape(self.n, 3)

    def symbolic_forces(self, X, V, S=None):
        f = ca.mtimes(ca.DM(self.K), ca.vec(X)) + ca.mtimes(ca.DM(self.D), ca.vec(V))
        return ca.reshape(f, 3, self.n)

    def symbolic_jacobians(self, X, V, S=None, decisions=None):
        return ca.DM(self.K), ca.DM(self.D)


@pytest.mark.parametrize("pinned", [(), (0,)])
def test_swapped_adjoint_is_exact_for_linear_forces(pinned):
    model = LinearModel(4, pinned)
    rng = np.random.default_rng(1)
    x0, v0 = rng.standard_normal((2, 4, 3))
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler(), x0=x0, v0=v0,
                          steps=10, dt=0.1, controls=StepForces(),
                          objective=StateKeyframe(10, x=np.zeros((4, 3)), v=np.zeros((4, 3)))
                          + StateKeyframe(5, x=np.ones((4, 3))) + Smoothness(1e-2))
    u = rng.standard_normal(prob.size)
    ga = prob.objective_and_gradient(u, "swapped")[1]
    ge = prob.objective_and_gradient(u, "casadi")[1]
    assert np.linalg.norm(ga - ge) < 1e-8 * np.linalg.norm(ge)


def contact_problem(dt=1 / 60, horizon=1 / 3, controls=None, solver="cg",
                    collision="guarded"):
    """5 x 5 sheet hanging from two corners, its lower edge resting on the ground (the issue's
    accuracy case, shared with the studies), default dt 1/60."""
    from casadi_keyframe.scenes.sheets import contact_problem as sheet
    return sheet(dt, horizon, solver=solver, controls=controls, collision=collision)


def swapped_and_exact(dt, seed=0, amp=0.05, **kw):
    prob = contact_problem(dt, **kw)
    u = amp * np.random.default_rng(seed).standard_normal(prob.size)
    grads = [prob.objective_and_gradient(u, route)[1] for route in ("swapped", "adjoint")]
    return grads, prob, u


@pytest.mark.parametrize("collision", ["guarded", "constraint", "penalty"])
def test_hand_exact_adjoint_equals_casadi_with_moving_contacts_and_attachments(collision):
    from casadi_keyframe.models import Attachment
    from casadi_keyframe.models.contact.colliders import Capsule, Contact, Sphere
    bodies = [Sphere(lambda t: np.array([0.5, 0.5, -0.33 + 0.2 * t]), 0.3),
              Capsule((0.0, 0.1, -0.1), lambda t: np.array([1.0, 0.2 + t, -0.06]), 0.05)]
    model = ClothModel.grid(4, 4, plane="xy", colliders=bodies, pinned=[3], collision=collision,
                            self_contact=Contact(200.0, 0.5, 0.3, 0.1),
                            attachments=[Attachment([0], lambda t: np.array([[0, 0.3 * t, 0]]))])
    x0 = model.rest_positions
    obj = StateKeyframe(12, x=x0 + [0.1, 0, -0.2], v=0 * x0) + CenterOfMassKeyframe(6, x=x0.mean(0))
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"),
                          x0=x0, v0=np.zeros_like(x0), steps=12, dt=1 / 30, controls=StepForces(),
                          objective=obj + Smoothness(1e-4))
    u = 0.1 * np.random.default_rng(0).standard_normal(prob.size)
    traj = prob.simulate(u)
    touching = [np.abs(model.forces(x, v, n / 30, role="contact")).max() > 0.1
                or (r.held is not None and r.held.count > 0)
                for n, (x, v, r) in enumerate(zip(traj.x, traj.v, traj.records))]
    assert sum(touching) >= 6  # in contact for half the steps
    f_hand, g_hand = prob.objective_and_gradient(u, "adjoint")
    f_ad, g_ad = prob.objective_and_gradient(u, "casadi")
    assert abs(f_hand - f_ad) < 1e-9 * abs(f_ad)
    # measured 4e-10: the two routes' trajectories differ by roundoff (4e-13 m after the
    # contacts start), which the contact stiffness's slope k / width = 4e5 N/m^2 amplifies
    assert np.linalg.norm(g_hand - g_ad) < 1e-8 * np.linalg.norm(g_ad)


def test_swapped_adjoint_with_contact_at_default_dt_and_its_order():
    """Swapped vs exact on a fixed horizon: cosine >= 0.99 at dt = 1/60 and the error shrinks
    with dt at a fitted order (measured: 0.094, 0.029, 0.0097 for dt = 1/60, 1/120, 1/240;
    order 1.6)."""
    dts = [1 / 60, 1 / 120, 1 / 240]
    errors = []
    for dt in dts:  # the paper's penalty contact: the published behaviour
        (ga, ge), prob, u = swapped_and_exact(dt, collision="penalty")
        errors.append(relative_error_and_cosine(ga, ge)[0])
        if dt == dts[0]:
            traj = prob.simulate(u)
            touching = [np.abs(prob.model.forces(x, v, role="contact")).max() > 0 for x, v in
                        zip(traj.x, traj.v)]
            assert np.mean(touching) > 0.5  # the collider is in contact most of the time
            assert relative_error_and_cosine(ga, ge)[1] >= 0.99
            f0 = prob.objective(u)
            assert prob.objective(u - 1e-3 * ga / np.linalg.norm(ga)) < f0  # descent
    order = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert errors[0] > errors[1] > errors[2] and order > 0.8, (errors, order)


def test_initial_velocity_control_gradients_for_cloth():
    from casadi_keyframe import InitialVelocity
    controls = InitialVelocity(agents=np.arange(2, 25))
    (ga, ge), prob, u = swapped_and_exact(1 / 60, amp=0.3, controls=controls, solver="direct")
    _, g_ad = prob.objective_and_gradient(u, "casadi")
    assert np.linalg.norm(ge - g_ad) < 1e-8 * np.linalg.norm(g_ad)
    assert relative_error_and_cosine(ga, ge)[1] >= 0.99


@pytest.mark.parametrize("solver", ["cg", "direct"])
def test_force_for_is_the_inverse_of_a_step(solver):
    """A step under the force ``force_for`` asks for ends on the asked velocities (free
    particles; pinned ones keep their prescribed rest), on a sheet in ground contact."""
    prob = contact_problem(solver=solver)
    model, integrator, dt = prob.model, prob.integrator, prob.dt
    rng = np.random.default_rng(3)
    x = prob.x0 + 0.01 * rng.standard_normal(prob.x0.shape)
    v = 0.3 * rng.standard_normal(x.shape)
    v1 = 0.3 * rng.standard_normal(x.shape)
    work = integrator.init(model)
    force = integrator.force_for(model, x, v, v1, 4, dt, work)
    end, record = integrator.step(model, State(x, v), force, 4, dt, work)
    x_end, v_end = end.x, end.v
    held = record.held  # their normal velocities are the step's, not v1's
    assert held is not None and held.count >= 3
    v1 = held.unheld_part(v1) + held.held_part(v + held.prescribed(v))
    free = model.free_mask().reshape(x.shape)
    assert not free.all() and np.abs(force).max() > 1.0
    np.testing.assert_allclose(v_end[free], v1[free], atol=1e-8)
    np.testing.assert_allclose(x_end[free], (x + dt * v1)[free], atol=1e-10)
    np.testing.assert_allclose(v_end[~free], model.prescribed_velocity(x, 4 * dt, dt)[~free],
                               atol=1e-12)


def test_routes_agree_at_rest_length_states():
    """A sheet at rest on the ground has every spring at its rest length up to round-off,
    where the Choi-Ko law has its kink: both routes must take the same branch there (they
    differed by 16 % when round-off decided it)."""
    from casadi_keyframe import load_problem

    prob = load_problem("cloth_toss", rows=4, cols=4, steps=40)
    u = prob.initial_controls()
    _, hand = prob.objective_and_gradient(u, "adjoint")
    _, casadi = prob.objective_and_gradient(u, "casadi")
    assert np.linalg.norm(hand - casadi) < 1e-6 * np.linalg.norm(casadi)
