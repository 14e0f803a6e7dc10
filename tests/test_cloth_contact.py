"""Colliders, self-contact and attachments: forces against CasADi, symmetric stiffness, a sheet
that rests on a sphere without passing through, a moving attachment that is followed."""
import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sp

from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.simulate import simulate
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models import Attachment
from casadi_keyframe.models.contact.colliders import Capsule, Contact, Plane, Sphere


def moving_scene():
    bodies = [Sphere(lambda t: np.array([0.5, 0.5, -0.3 + 0.1 * t]), 0.3),
              Plane((0, 0, -0.05), (0.1, 0, 1)),
              Capsule((0, 0.2, -0.04), lambda t: np.array([1.0, 0.3 + t, -0.02]), 0.03)]
    return ClothModel.grid(4, 4, plane="xy", colliders=bodies, collision="penalty",
                           self_contact=Contact(500.0, 0.5, 0.4, 0.1))


def jammed_state(model, seed=0):
    rng = np.random.default_rng(seed)
    x = model.rest_positions * [0.6, 0.6, 1] + 0.03 * rng.standard_normal((model.n, 3))
    return x, rng.standard_normal((model.n, 3))


def casadi_derivatives(model, x, v, t):
    """Forces, ``df/dx`` at zero velocity, ``df/dv`` and the symbolic (K, D), all by CasADi."""
    X, V = ca.SX.sym("X", 3, model.n), ca.SX.sym("V", 3, model.n)
    S = ca.DM(model.scene_parameters(t))
    f = model.symbolic_forces(X, V, S)
    f0 = model.symbolic_forces(X, ca.SX.zeros(3, model.n), S)
    fn = ca.Function("f", [X, V], [f, ca.jacobian(ca.vec(f0), ca.vec(X)),
                                   ca.jacobian(ca.vec(f), ca.vec(V)),
                                   *model.symbolic_jacobians(X, V, S)])
    return [np.array(a) for a in fn(x.T, v.T)]


def test_contact_forces_and_jacobians_match_casadi():
    model = moving_scene()
    x, v = jammed_state(model)
    t = 0.3
    f_sym, _, D_sym, K_step, D_step = casadi_derivatives(model, x, v, t)
    contact = model.forces(x, v, t, role="contact")
    assert np.abs(contact).max() > 1.0  # the state really is in contact
    np.testing.assert_allclose(model.forces(x, v, t), f_sym.T, atol=1e-9)
    K, D = model.jacobians(x, v, t)
    np.testing.assert_allclose(D.toarray(), D_sym, atol=1e-8)
    np.testing.assert_allclose(K.toarray(), K_step, atol=1e-9)
    np.testing.assert_allclose(D.toarray(), D_step, atol=1e-9)
    assert abs(K - K.T).max() < 1e-9 and abs(D - D.T).max() < 1e-9
    assert np.linalg.eigvalsh(K.toarray()).max() < 1e-9 * abs(K).max()


def ramp(p, width):
    return np.where(p <= 0, 0, np.where(p <= width, p ** 2 / (2 * width), p - width / 2))


def curvature(d, r):
    """``I/r - d d^T/r^3`` per row of d, row-major ``(k, 9)``."""
    return (np.eye(3) / r[:, None, None]
            - np.einsum("pa,pb->pab", d, d) / r[:, None, None] ** 3).reshape(-1, 9)


def test_contact_stiffness_is_df_dx_without_curvature_terms():
    """K + (spring transverse + sphere curvature + self-contact transverse terms) = df/dx."""
    from test_cloth_model import transverse_blocks

    from casadi_keyframe.models.blocks import pair_block_matrices
    sphere = Sphere((0.3, 0.3, -0.25), 0.3)
    contact = Contact(500.0, 0.5, 0.4, 0.1)
    model = ClothModel.grid(4, 4, plane="xy", colliders=[sphere, Plane((0, 0, -0.05))],
                            collision="penalty",
                            self_contact=contact)
    x, v = jammed_state(model)
    _, jx, _, _, _ = casadi_derivatives(model, x, v, 0.0)
    K = model.jacobians(x, v)[0]
    s, n = model.springs, model.n
    dropped = pair_block_matrices(s.i, s.j, n, transverse_blocks(model, x))[0].toarray()
    d = x - sphere.center
    r = np.sqrt(np.einsum("pk,pk->p", d, d) + 1e-12)
    k, _, h, width = sphere.contact.gains
    bend = k * ramp(h - (r - sphere.radius), width)[:, None] * curvature(d, r)
    assert np.abs(bend).max() > 1.0  # the sphere's curvature term is really there
    dropped += sp.block_diag([b.reshape(3, 3) for b in bend]).toarray()
    i, j = model.family("self-contact").find(x)
    dp = x[j] - x[i]
    rp = np.sqrt(np.einsum("pk,pk->p", dp, dp) + 1e-12)
    assert i.size
    pair = -contact.stiffness * ramp(contact.thickness - rp, contact.width)[:, None] * curvature(dp, rp)
    dropped += pair_block_matrices(i, j, n, pair)[0].toarray()
    np.testing.assert_allclose(K.toarray() + dropped, jx, atol=1e-8 * np.abs(jx).max())


def test_self_contact_forces_sum_to_zero_and_skip_springs():
    model = ClothModel.grid(4, 4, plane="xy", params=None, self_contact=Contact(thickness=0.5),
                            colliders=[])
    x, v = jammed_state(model, 1)
    fc = model.forces(x, v, role="contact")
    np.testing.assert_allclose(fc.sum(0), 0, atol=1e-10)
    i, j = model.family("self-contact").find(x)
    joined = set(zip(model.springs.i.tolist(), model.springs.j.tolist()))
    assert i.size and not {(a, b) for a, b in zip(i, j)} & (joined | {(b, a) for a, b in joined})


def test_sheet_resting_on_a_sphere_does_not_pass_through():
    sphere = Sphere((0.5, 0.5, -0.32), 0.3)
    model = ClothModel.grid(7, 7, plane="xy", colliders=[sphere, Plane((0, 0, -0.7))])
    x0 = model.rest_positions
    traj = simulate(LinearizedBackwardEuler(), model, x0, np.zeros_like(x0),
                                             np.zeros((90, model.n, 3)), 1 / 60)
    gap = np.linalg.norm(traj.x - sphere.center, axis=2) - sphere.radius
    assert gap.min() > -0.01  # never deeper than the thickness into the sphere
    assert traj.x[:, :, 2].min() > -0.7 - 0.01  # nor through the ground
    assert gap[-1].min() < sphere.contact.thickness  # and it does rest on it


def test_attached_particles_follow_their_path_and_pins_stay():
    path = lambda t: np.array([[0.0, 0.5 * t, np.sin(2 * t)]])  # noqa: E731
    model = ClothModel.grid(3, 3, pinned=[2], attachments=[Attachment([0], path)])
    x0 = model.rest_positions
    traj = simulate(LinearizedBackwardEuler(), model, x0, np.zeros_like(x0),
                                             np.zeros((20, model.n, 3)), 0.05)
    for n in range(1, 21):
        np.testing.assert_allclose(traj.x[n, 0], path(n * 0.05)[0], atol=1e-12)
    assert np.all(traj.x[:, 2] == x0[2])


@pytest.mark.parametrize("bad, message", [
    (dict(colliders=["ball"]), "colliders must be"),
    (dict(attachments=[Attachment([0], lambda t: np.zeros((1, 3)))], pinned=[0]), "twice"),
    (dict(friction=1.0), "unknown cloth option"),
])
def test_bad_scene_is_refused_clearly(bad, message):
    with pytest.raises((ValueError, TypeError), match=message):
        ClothModel.grid(3, 3, **bad)


def test_bad_colliders_are_refused_clearly():
    with pytest.raises(ValueError, match="radius must be positive"):
        Sphere((0, 0, 0), -1.0)
    with pytest.raises(ValueError, match="3 finite numbers"):
        Capsule((0, 0), (1, 0, 0), 0.1)
    with pytest.raises(ValueError, match="must return"):
        Attachment([0, 1], lambda t: np.zeros((1, 3)))


def test_a_blown_up_cloth_is_reported_not_returned():
    from casadi_keyframe import SimulationError
    model = ClothModel.grid(12, 12, pinned=[0, 11])
    x0 = model.rest_positions
    pull = np.zeros((30, model.n, 3))
    pull[:, -1] = [0, 0, -2000.0]  # an absurd control on one corner
    with pytest.raises(SimulationError, match="blew up"):
        simulate(LinearizedBackwardEuler(), model, x0, np.zeros_like(x0), pull, 1 / 30)


def test_a_sphere_sweeping_through_the_sheet_stays_stable():
    """A sphere moving 2.7 cm per step against a 1 cm contact layer (before the stiffness
    was clamped this sent the sheet to 460 m, or made the step matrix indefinite)."""
    sphere = Sphere(lambda t: np.array([0.5, -0.3 + 0.8 * t, -0.5]), 0.2)
    model = ClothModel.grid(12, 12, pinned=[0, 11], colliders=[sphere])
    x0 = model.rest_positions
    traj = simulate(LinearizedBackwardEuler(), model, x0, np.zeros_like(x0),
                                             np.zeros((30, model.n, 3)), 1 / 30)
    centers = np.array([sphere.center(n / 30) for n in range(31)])
    gap = np.linalg.norm(traj.x - centers[:, None], axis=2) - sphere.radius
    assert gap.min() > -0.03 and model.max_stretch(traj.x[-1]) < 1.5
    assert traj.x[-1, :, 1].max() > 0.5  # the sheet was pushed along


def test_physical_report_finds_the_deepest_particle_and_the_largest_stretch():
    """A 3 x 3 sheet (spacing 0.5 m): a sphere dips 0.2 m into its middle particle at frame 1
    and leaves; a spring is stretched 1.5x at frame 2; plane and capsule depths by their
    geometry."""
    ball = Sphere(lambda t: np.array([0.5, 0.5, 0.3 - 4 * t + 20 * t ** 2]), 0.3)
    ground = Plane((0, 0, -1.0), (0, 0, 1))
    rod = Capsule((-5.0, 0, 0), (-5.0, 2, 0), 0.1)
    model = ClothModel.grid(3, 3, plane="xy", colliders=[ball, ground, rod])
    x = np.repeat(model.rest_positions[None], 3, axis=0)
    x[2, 0] -= [0.25, 0, 0]  # the spring from particle 0 to 1 (rest 0.5) is now 0.75 long
    report = model.physical_report(x, 0.1)
    assert report["max_penetration"] == pytest.approx(0.2, abs=1e-9)
    assert report["max_penetration_frame"] == 1
    assert report["max_stretch"] == pytest.approx(1.5, rel=1e-3) and report["max_stretch_frame"] == 2
    assert model.penetration(model.rest_positions - [0, 0, 1.05], 0.2) == pytest.approx(0.05)
    inside_rod = model.rest_positions.copy()
    inside_rod[8] = [-5.0, 1.0, 0.07]
    assert model.penetration(inside_rod, 0.2) == pytest.approx(0.03)
