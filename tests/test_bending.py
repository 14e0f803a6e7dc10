"""Dihedral bending, a law on four particles given to a cloth as one family: its forces sum
to zero, its Jacobian blocks are CasADi's Jacobian of its forces (K the clamped,
negative semi-definite part), the exact adjoint through it is CasADi's reverse mode and
central differences, and a clamped sheet bends less with it."""
import casadi as ca
import numpy as np
import pytest

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel, Contact, Plane
from casadi_keyframe.models.bending import DihedralBending
from casadi_keyframe.models.blocks import BlockPattern
from casadi_keyframe.simulate import simulate


def bent(model, seed=0, scale=0.05):
    rng = np.random.default_rng(seed)
    return (model.rest_positions + scale * rng.standard_normal((model.n, 3)),
            rng.standard_normal((model.n, 3)))


def sheet_with_bending(rows=4, cols=4, stiffness=0.1, damping=0.01, **scene):
    sheet = ClothModel.grid(rows, cols, plane="xy")
    bending = DihedralBending.of(sheet, stiffness=stiffness, damping=damping)
    return ClothModel.grid(rows, cols, plane="xy", families=[bending], **scene), bending


def rotated(x, angle=0.7):
    c, s = np.cos(angle), np.sin(angle)
    return x @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [0.3, -0.2, 0.5]


def test_bending_forces_sum_to_zero_and_vanish_at_rest():
    model, bending = sheet_with_bending()
    x, v = bent(model)
    f = bending.forces(x, v, 0.0, None)
    assert np.abs(f).max() > 1.0
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * np.abs(f).max() * model.n
    torque = np.cross(x, f).sum(axis=0)  # rigid rotations change no angle
    assert np.abs(torque).max() < 1e-12 * np.abs(f).max() * model.n
    still = rotated(model.rest_positions)
    assert np.abs(bending.forces(still, np.zeros_like(still), 0.0, None)).max() < 1e-12
    assert model.family("dihedral bending") is bending and bending.role == "internal"


def test_bending_blocks_are_casadi_s_jacobian_and_k_is_its_clamped_part():
    model, bending = sheet_with_bending()
    x, v = bent(model)
    X, V = ca.SX.sym("X", 3, model.n), ca.SX.sym("V", 3, model.n)
    F = ca.vec(bending.symbolic_forces(X, V, ca.DM()))
    jacobian = ca.Function("jacobian", [X, V], [ca.jacobian(F, ca.vec(X)), ca.jacobian(F, ca.vec(V))])
    pattern = BlockPattern(np.zeros(0), np.zeros(0), model.n, particle_blocks=False,
                           stencils=(bending.stencils,))
    no_pairs = np.zeros((0, 9))

    def matrices(x, v):
        K, D, J = bending.blocks(x, v, 0.0, ("jac", "df_dx"), None).stencil_blocks
        return [pattern.matrix(no_pairs, None, (b,)).toarray() for b in (K, D, J)]

    K, D, J = matrices(x, v)
    J_ref, D_ref = (np.array(a) for a in jacobian(x.T, v.T))
    np.testing.assert_allclose(J, J_ref, atol=1e-12 * np.abs(J_ref).max())
    np.testing.assert_allclose(D, D_ref, atol=1e-12 * np.abs(D_ref).max())
    for M in (K, D):  # symmetric, negative semi-definite: the step matrix stays SPD
        np.testing.assert_allclose(M, M.T, atol=1e-12 * np.abs(M).max())
        assert np.linalg.eigvalsh(M).max() < 1e-10 * np.abs(M).max()
    assert np.abs(K - J).max() > 0.01 * np.abs(J).max()  # bent: the angles' curvature is out
    still = rotated(model.rest_positions)
    K0, _, J0 = matrices(still, np.zeros_like(still))  # at rest angles K is all of df/dx
    np.testing.assert_allclose(K0, J0, atol=1e-12 * np.abs(J0).max())
    K_model, D_model, J_model = model.jacobians(x, v, 0.0, with_df_dx=True)
    F_model = ca.vec(model.symbolic_forces(X, V))
    J_all = np.array(ca.Function("j", [X, V], [ca.jacobian(F_model, ca.vec(X))])(x.T, v.T))
    np.testing.assert_allclose(J_model.toarray(), J_all, atol=1e-12 * np.abs(J_all).max())
    K_sym, D_sym = model.symbolic_jacobians(X, V)
    K_sym = np.array(ca.Function("k", [X, V], [ca.densify(K_sym)])(x.T, v.T))
    np.testing.assert_allclose(K_model.toarray(), K_sym, atol=1e-12 * np.abs(K_sym).max())


def test_stencil_blocks_times_a_vector_is_the_matrix_times_it():
    model, _ = sheet_with_bending()
    x, v = bent(model)
    y = np.random.default_rng(3).standard_normal((model.n, 3))
    for blocks, matrix in zip(model.jacobian_blocks(x, v, 0.0, with_df_dx=True),
                              model.jacobians(x, v, 0.0, with_df_dx=True)):
        assert blocks.stencils and blocks.stencils[0][1].shape[1] == 144
        np.testing.assert_allclose(blocks.matvec(y).ravel(), matrix @ y.ravel(), atol=1e-11)
        np.testing.assert_allclose(blocks.matvec(y, transpose=True).ravel(),
                                   matrix.T @ y.ravel(), atol=1e-11)


def ground_problem(steps=12, dt=1 / 30, solver="direct"):
    """A 4 x 4 sheet with bending falling onto the ground, which holds it, with self-contact."""
    model, _ = sheet_with_bending(pinned=[0], colliders=[Plane((0, 0, -0.03))],
                                  self_contact=Contact(200.0, 0.5, 0.3, 0.1))
    x0 = model.rest_positions
    objective = (StateKeyframe(steps, x=x0 + [0.1, 0.2, 0.05], v=0 * x0) + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(solver), x0=x0,
                          v0=np.zeros_like(x0), steps=steps, dt=dt, controls=StepForces(),
                          objective=objective)


def test_the_exact_adjoint_through_bending_is_casadi_s_and_differences():
    prob = ground_problem()
    u = 0.1 * np.random.default_rng(0).standard_normal(prob.size)
    traj = prob.simulate(u)
    assert any(r.held is not None for r in traj.records)  # the hold projects hinge blocks
    f, g = prob.objective_and_gradient(u, "adjoint")
    f_ref, g_ref = prob.objective_and_gradient(u, "casadi")
    assert f == pytest.approx(f_ref, rel=1e-10)
    assert np.linalg.norm(g - g_ref) <= 1e-8 * np.linalg.norm(g_ref)
    d = np.random.default_rng(1).standard_normal(prob.size)
    h = 1e-6
    slope = (prob.objective(u + h * d) - prob.objective(u - h * d)) / (2 * h)
    assert g @ d == pytest.approx(slope, rel=1e-5)
    assert prob.directional_derivative(u, d) == pytest.approx(g_ref @ d, rel=1e-8)


@pytest.mark.parametrize("solver", ["cholmod", "cg"])
def test_every_solver_steps_the_bending_sheet_alike(solver):
    prob, other = ground_problem(), ground_problem(solver=solver)
    u = 0.1 * np.random.default_rng(0).standard_normal(prob.size)
    np.testing.assert_allclose(other.simulate(u).x, prob.simulate(u).x, atol=1e-8)


def test_a_clamped_sheet_bends_less_with_bending():
    """A horizontal sheet clamped along two rows sags under gravity: less, and with flatter
    hinges, with the bending family than without."""
    sheet = ClothModel.grid(6, 6, plane="xy")
    bending = DihedralBending.of(sheet, stiffness=1.0, damping=0.1)
    ends = []
    for families in ([], [bending]):
        model = ClothModel.grid(6, 6, plane="xy", pinned=range(12), families=families)
        traj = simulate(LinearizedBackwardEuler("direct"), model, model.rest_positions,
                        np.zeros((model.n, 3)), np.zeros((60, model.n, 3)), 1 / 60)
        ends.append(traj.x[-1])
    (limp, stiff), angles = ends, [np.abs(bending.angles(x)).max() for x in ends]
    assert stiff[:, 2].min() > limp[:, 2].min() + 0.1
    assert angles[1] < 0.5 * angles[0]


def test_bending_refuses_bad_input():
    sheet = ClothModel.grid(3, 3)
    with pytest.raises(ValueError, match="stiffness must be non-negative"):
        DihedralBending.of(sheet, stiffness=-1.0)
    with pytest.raises(ValueError, match="interior edge"):
        DihedralBending(np.eye(3), [[0, 1, 2]], stiffness=1.0)
