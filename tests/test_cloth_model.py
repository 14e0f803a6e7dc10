"""The cloth's forces: topology, the buckling law, numeric against symbolic, bad input."""
import casadi as ca
import numpy as np
import pytest

from casadi_keyframe.models import ClothModel, ClothParams
from casadi_keyframe.models.blocks import pair_block_matrices
from casadi_keyframe.models.springs import SHEAR, STRETCH, sinc_inverse, spring_kernels


@pytest.fixture(scope="module")
def grid45():
    # a stiff bend, so compressed springs push hard enough for their transverse term to show
    return ClothModel.grid(4, 5, mass=0.3, pinned=[0, 4],
                           params=ClothParams(damping=0.05, air_drag=0.2, bend=2e-2))


def perturbed(model, seed=0, scale=0.08, vscale=1.0):
    rng = np.random.default_rng(seed)
    x = model.rest_positions + scale * rng.standard_normal((model.n, 3))
    return x, vscale * rng.standard_normal((model.n, 3))


def stretch_ratio(model, x):
    s = model.springs
    return np.linalg.norm(x[s.j] - x[s.i], axis=1) / s.rest


def symbolic(model, x, v, jacobians=False):
    X, V = ca.SX.sym("X", 3, model.n), ca.SX.sym("V", 3, model.n)
    f = model.symbolic_forces(X, V)
    outs = [f]
    if jacobians:  # stiffness at zero velocity, damping from the full force
        f0 = model.symbolic_forces(X, ca.SX.zeros(3, model.n))
        outs = [ca.jacobian(ca.vec(f0), ca.vec(X)), ca.jacobian(ca.vec(f), ca.vec(V))]
    res = ca.Function("f", [X, V], outs)(x.T, v.T)
    res = res if isinstance(res, (list, tuple)) else [res]
    return [np.array(r) for r in res]


def test_sinc_inverse_fit_is_accurate():
    y = np.linspace(0, np.pi, 20001)
    s = np.sinc(y / np.pi)  # numpy's sinc is sin(pi t) / (pi t)
    assert np.abs(sinc_inverse(s) - y).max() < 1e-4
    assert sinc_inverse(np.array([1.0]))[0] == 0.0


def test_buckling_force_matches_the_arc_model():
    force = spring_kernels(1e-12)["force"]
    L, kb = 0.2, 3e-4
    for s in (0.1, 0.5, 0.9, 0.999):
        y = sinc_inverse(np.array([s]))[0]
        assert abs(np.sin(y) / y - s) < 1e-5
        f = np.array(force([s * L, 0, 0], [0, 0, 0], L, 100.0, kb, 0.0, 0.0)).ravel()
        np.testing.assert_allclose(f, [-kb * (2 * y / L) ** 2, 0, 0], rtol=1e-9)
    f = np.array(force([1.5 * L, 0, 0], [1.0, 0, 0], L, 100.0, kb, 0.3, 0.0)).ravel()
    np.testing.assert_allclose(f, [100.0 * 0.5 * L + 0.3, 0, 0], rtol=1e-9)


def test_grid_spring_counts_and_faces():
    model = ClothModel.grid(3, 4)
    s = model.springs
    assert (s.count("stretch"), s.count("shear"), s.count("bend")) == (17, 12, 10)
    assert model.faces.shape == (2 * 2 * 3, 3) and model.n == 12 and model.dim == 3
    np.testing.assert_allclose(model.masses.sum(), 1.0)
    assert model.masses[0] == pytest.approx(model.masses[5] / 4)  # corner vs inner
    assert model.masses[3] == pytest.approx(model.masses[0])  # symmetric
    np.testing.assert_allclose(s.rest[s.kind == STRETCH][:9], 1 / 3)  # horizontal
    np.testing.assert_allclose(s.rest[s.kind == SHEAR], np.hypot(1 / 3, 1 / 2))
    flat = ClothModel.grid(3, 4, plane="xy", origin=(1, 2, 3))
    assert np.all(flat.rest_positions[:, 2] == 3) and flat.rest_positions[-1, 1] == 3.0
    assert ClothModel.grid(3, 4).rest_positions[:, 2].max() == 0  # hangs below the origin


def test_from_mesh_of_the_grid_triangles():
    grid = ClothModel.grid(3, 4)
    mesh = ClothModel.from_mesh(grid.rest_positions, grid.faces)

    def pairs(model, kind):
        s = model.springs
        sel = s.kind == kind
        return {tuple(sorted(p)) for p in zip(s.i[sel], s.j[sel])}

    mesh_edges = pairs(mesh, STRETCH)
    assert pairs(grid, STRETCH) <= mesh_edges
    assert mesh_edges - pairs(grid, STRETCH) <= pairs(grid, SHEAR)  # the one split diagonal
    assert len(mesh_edges) == 17 + 6 and mesh.springs.count("shear") == 0
    assert mesh.springs.count("bend") == 17 + 6 - (2 * 3 + 2 * 2)  # interior edges
    np.testing.assert_allclose(mesh.masses.sum(), grid.masses.sum())  # lumped per triangle


def test_internal_forces_sum_to_zero(grid45):
    x, v = perturbed(grid45)
    f = grid45.forces(x, v, role="internal")
    assert np.abs(f).max() > 1.0
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-10)


def test_rest_state_feels_only_gravity(grid45):
    x, v = grid45.rest_positions, np.zeros((grid45.n, 3))
    np.testing.assert_allclose(grid45.forces(x, v, role="internal"), 0.0, atol=1e-12)
    np.testing.assert_allclose(grid45.forces(x, v),
                               grid45.masses[:, None] * np.array([0, 0, -9.81]), atol=1e-12)


def test_symbolic_forces_equal_numeric(grid45):
    x, v = perturbed(grid45, seed=1)
    (sym,) = symbolic(grid45, x, v)
    np.testing.assert_allclose(sym.T, grid45.forces(x, v), atol=1e-10)


def transverse_blocks(model, x):
    """The row-major ``(P, 9)`` blocks ``min(m, 0) (I/r - d d^T/r^3)`` the step's stiffness
    leaves out of ``df_i/dd`` (compressed springs' transverse term), from the force alone."""
    s, eps = model.springs, model.params.eps
    d = x[s.j] - x[s.i]
    r = np.sqrt(np.einsum("pk,pk->p", d, d) + eps ** 2)
    force = spring_kernels(eps)["force"].map(s.i.size)
    f = np.array(force(d.T, np.zeros_like(d.T), *[a.T for a in model.family("springs").pair_parameters(s.i, s.j)])).T
    m = np.einsum("pk,pk->p", f, d) * r / np.einsum("pk,pk->p", d, d)  # f = m d / r
    outer = np.einsum("pa,pb->pab", d, d) / r[:, None, None] ** 3
    return (np.minimum(m, 0)[:, None, None] * (np.eye(3) / r[:, None, None] - outer)).reshape(-1, 9)


def test_sparse_jacobians_are_casadi_without_the_compressed_transverse_term(grid45):
    x, v = perturbed(grid45, seed=2)
    ratio = stretch_ratio(grid45, x)
    assert np.any(ratio < 1) and np.any(ratio > 1)  # both branches of the law are exercised
    jx, jv = symbolic(grid45, x, v, jacobians=True)
    dfdx, dfdv = grid45.jacobians(x, v)
    assert dfdx.format == "csc" and dfdx.shape == (3 * grid45.n,) * 2
    s = grid45.springs
    (dropped,) = pair_block_matrices(s.i, s.j, grid45.n, transverse_blocks(grid45, x))
    assert abs(dropped).max() > 1e-3 * abs(jx).max()
    np.testing.assert_allclose((dfdx + dropped).toarray(), jx, atol=1e-8 * np.abs(jx).max())
    np.testing.assert_allclose(dfdv.toarray(), jv, atol=1e-12)
    assert np.array_equal(dfdx.indices, grid45.jacobians(*perturbed(grid45, 5))[0].indices)


def test_stiffness_is_negative_semidefinite_where_df_dx_is_not(grid45):
    x, v = perturbed(grid45, seed=2)
    (jx,) = [symbolic(grid45, x, v, jacobians=True)[0]]
    K = grid45.jacobians(x, v)[0].toarray()
    scale = np.abs(jx).max()
    assert np.linalg.eigvalsh(jx).max() > 1e-3 * scale  # df/dx has unstable directions
    assert np.linalg.eigvalsh(K).max() < 1e-10 * scale  # the step's K has none


def test_symbolic_jacobians_equal_numeric(grid45):
    x, v = perturbed(grid45, seed=4)
    X, V = ca.SX.sym("X", 3, grid45.n), ca.SX.sym("V", 3, grid45.n)
    K, D = ca.Function("j", [X, V], list(grid45.symbolic_jacobians(X, V)))(x.T, v.T)
    Kn, Dn = grid45.jacobians(x, v)
    np.testing.assert_allclose(np.array(K), Kn.toarray(), atol=1e-12 * abs(Kn).max())
    np.testing.assert_allclose(np.array(D), Dn.toarray(), atol=1e-14)


def test_jacobian_symmetry(grid45):
    x, v = perturbed(grid45, seed=3)
    dfdx, dfdv = grid45.jacobians(x, v)
    assert abs(dfdv - dfdv.T).max() < 1e-12
    assert abs(dfdx - dfdx.T).max() < 1e-9 * abs(dfdx).max()
    # the full position derivative is not symmetric when particles move relative to each
    # other (damping is not conservative): that part is what K leaves out
    (full,) = [np.array(m) for m in _full_position_jacobian(grid45, x, v)]
    assert np.abs(full - full.T).max() > 1e-6


def _full_position_jacobian(model, x, v):
    X, V = ca.SX.sym("X", 3, model.n), ca.SX.sym("V", 3, model.n)
    f = ca.vec(model.symbolic_forces(X, V))
    return [ca.Function("j", [X, V], [ca.jacobian(f, ca.vec(X))])(x.T, v.T)]


@pytest.mark.parametrize("call, message", [
    (lambda: ClothModel.grid(1, 5), "rows >= 2"),
    (lambda: ClothModel.grid(3, 3, mass=-1.0), "total mass must be a positive"),
    (lambda: ClothModel.grid(3, 3, pinned=[9]), "pinned particle indices"),
    (lambda: ClothModel.grid(3, 3, plane="yz"), "plane must be one of"),
    (lambda: ClothModel.from_mesh(np.eye(3), [[0, 1, 3]]), "faces index vertices"),
    (lambda: ClothModel.from_mesh(np.eye(3), [[0.0, 1.0, 2.0]]), "integer array"),
    (lambda: ClothModel.from_mesh(np.vstack([np.eye(3), [[1, 1, 1]]]), [[0, 1, 2]]),
     "every vertex must belong"),
    (lambda: ClothParams(stretch=-1.0), "ClothParams.stretch"),
])
def test_bad_input_raises(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_bad_state_shape_raises(grid45):
    with pytest.raises(ValueError, match=r"x must have shape \(20, 3\)"):
        grid45.forces(np.zeros((3, 20)), np.zeros((20, 3)))


def test_flat_hanging_sheet_has_a_meaningful_gradient():
    """A sheet hanging in its plane is compressed across its width and stays exactly planar
    when passive.  A compressive force that resists like a strut makes that state a buckling
    saddle (every compressed spring has transverse stiffness m / r < 0), along which the
    gradient grew 1e11-fold over two seconds while central differences gave +42 or -3.6e4
    depending on h.  With the Choi-Ko post-buckling load the gradient is what differences say."""
    from casadi_keyframe import load_problem
    from casadi_keyframe.adjoints import FiniteDifference

    prob = load_problem("cloth_shapes", rows=8, cols=8, steps=60)
    u = prob.initial_controls()
    assert np.abs(prob.simulate(u).x[..., 1]).max() == 0.0  # passive: exactly planar
    _, g = prob.objective_and_gradient(u)
    d = g / np.linalg.norm(g)
    slopes = [FiniteDifference(h).directional(prob, u, d) for h in (1e-4, 1e-6)]
    np.testing.assert_allclose(slopes, np.linalg.norm(g), rtol=1e-3)
