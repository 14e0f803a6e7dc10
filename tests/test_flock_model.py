"""The flock's forces: fast paths against slow paths, physics sanity, bad input."""
import casadi as ca
import numpy as np
import pytest

from casadi_keyframe.kernels import MappedKernel, jit_available
from casadi_keyframe.models import FlockModel, FlockParams, wander_forces
from casadi_keyframe.models.flock import PairTape, pair_kernels
from casadi_keyframe import problem as problem_module
from casadi_keyframe.simulate import backward, simulate
from casadi_keyframe.state import Trajectory
from helpers import small_flock


def random_state(n, dim, seed=0, size=8.0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, size, (n, dim)), rng.standard_normal((n, dim))


@pytest.mark.parametrize("dim", [2, 3])
def test_neighbour_list_equals_all_pairs(cutoff, dim):
    model = FlockModel(np.ones(300), dim, FlockParams(cutoff=cutoff))
    x, v = random_state(300, dim, size=30.0)
    tape = model.interactions(x)
    fast = model.forces(x, v, 0.0, tape)
    slow = model.forces(x, v, 0.0, model.all_pairs())
    assert tape.i.size < model.all_pairs().i.size / 5  # the list really is sparse
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12 * np.abs(slow).max())


def test_internal_forces_sum_to_zero(cutoff):
    model = FlockModel(np.random.default_rng(1).uniform(0.5, 2, 100), 3, FlockParams(cutoff=cutoff))
    x, v = random_state(100, 3)
    f = model.forces(x, v)
    assert np.abs(f).max() > 1.0
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-11)


def test_symbolic_forces_equal_numeric(cutoff):
    model = FlockModel(np.ones(20), 2, FlockParams(cutoff=cutoff, drag=0.3))
    x, v = random_state(20, 2, size=4.0)
    X, V = ca.MX.sym("X", 2, 20), ca.MX.sym("V", 2, 20)
    sym = ca.Function("f", [X, V], [model.symbolic_forces(X, V)])
    np.testing.assert_allclose(np.array(sym(x.T, v.T)).T, model.forces(x, v), atol=1e-12)


def test_vjp_equals_transposed_jacobian(cutoff):
    model = FlockModel(np.ones(15), 2, FlockParams(cutoff=cutoff, drag=0.2))
    x, v = random_state(15, 2, size=3.0, seed=3)
    mu = np.random.default_rng(4).standard_normal((15, 2))
    X, V = ca.SX.sym("X", 2, 15), ca.SX.sym("V", 2, 15)
    f = ca.vec(model.symbolic_forces(X, V))
    jac = ca.Function("j", [X, V], [ca.jacobian(f, ca.vec(X)), ca.jacobian(f, ca.vec(V))])
    jx, jv = (np.array(m) for m in jac(x.T, v.T))
    tape = model.interactions(x)
    gx, gv = model.forces_vjp(x, v, 0.0, tape, mu)
    np.testing.assert_allclose(gx.ravel(), jx.T @ mu.ravel(), atol=1e-11)
    np.testing.assert_allclose(gv.ravel(), jv.T @ mu.ravel(), atol=1e-11)
    dx, dv = np.random.default_rng(5).standard_normal((2, 15, 2))
    df = model.forces_jvp(x, v, 0.0, tape, dx, dv)
    np.testing.assert_allclose(df.ravel(), jx @ dx.ravel() + jv @ dv.ravel(), atol=1e-11)


def test_smooth_cutoff_vanishes_with_its_derivative_at_the_radius():
    p = FlockParams(cutoff="smooth", eps=1e-9)
    force = pair_kernels(2, p)["force"]
    d = ca.SX.sym("d", 2)
    f = force(d, ca.DM.zeros(2))
    jac = ca.Function("j", [d], [f, ca.jacobian(f, d)])
    for radius in (p.avoid_radius, p.center_radius):
        for side in (1 - 1e-7, 1 + 1e-7):
            val, der = jac(ca.DM([radius * side, 0]))
            if radius == p.center_radius:
                assert np.abs(np.array(val)).max() < 1e-6 and np.abs(np.array(der)).max() < 1e-5


def test_mapped_kernel_jit_equals_virtual_machine_and_plain_call():
    force = pair_kernels(3, FlockParams())["force"]
    d, dv = np.random.default_rng(5).standard_normal((2, 2100, 3))
    vm = MappedKernel(force, jit=False)(d, dv)[0]
    plain = np.array(force.map(2100)(d.T, dv.T)).T
    np.testing.assert_allclose(vm, plain, atol=1e-14)
    if jit_available():
        np.testing.assert_allclose(MappedKernel(force, jit=True)(d, dv)[0], vm, atol=1e-12)


def test_mapped_kernel_writes_a_structurally_sparse_output_densely():
    """A buffer holds an output's nonzeros only: a constant diagonal block must still land
    on the diagonal (it filled every entry before outputs were made dense)."""
    x, c = ca.SX.sym("x", 3), ca.SX.sym("c")
    kernel = ca.Function("damping", [x, c], [ca.reshape(-c * ca.SX.eye(3), 9, 1), x * c])
    assert not kernel.sparsity_out(0).is_dense()
    xs, cs = np.random.default_rng(6).standard_normal((5, 3)), np.full((5, 1), 0.2)
    for jit in (False, True) if jit_available() else (False,):
        block, scaled = MappedKernel(kernel, jit=jit)(xs, cs)
        np.testing.assert_array_equal(block, np.tile(-0.2 * np.eye(3).ravel(), (5, 1)))
        np.testing.assert_allclose(scaled, 0.2 * xs)


def test_mapped_kernel_rejects_wrong_shapes():
    force = pair_kernels(2, FlockParams())["force"]
    with pytest.raises(ValueError, match="shape"):
        MappedKernel(force, jit=False)(np.zeros((5, 3)), np.zeros((5, 2)))


def test_wander_is_drawn_once_from_the_seed():
    a = wander_forces(50, 10, 2, strength=0.5, seed=7)
    np.testing.assert_array_equal(a, wander_forces(50, 10, 2, strength=0.5, seed=7))
    assert not np.allclose(a, wander_forces(50, 10, 2, strength=0.5, seed=8))
    assert 0.3 < a.std() < 0.7


@pytest.mark.parametrize("kwargs, match", [
    ({"masses": [1.0, -1.0]}, "mass"),
    ({"masses": [1.0, np.nan]}, "mass"),
    ({"masses": [1.0], "dim": 4}, "dimensions"),
])
def test_bad_models_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FlockModel(**kwargs)


def test_bad_params_are_refused():
    with pytest.raises(ValueError, match="cutoff"):
        FlockParams(cutoff="soft")
    with pytest.raises(ValueError, match="avoid_radius"):
        FlockParams(avoid_radius=0.0)


def test_pair_tapes_are_compact_and_the_adjoint_is_unchanged():
    prob = small_flock()
    u = 0.3 * np.random.default_rng(0).standard_normal(prob.size)
    traj = prob.simulate(u)
    assert all(t.i.dtype == t.j.dtype == np.uint8 for t in traj.records)  # 8 agents
    wide = Trajectory(traj.x, traj.v, traj.dt,
                      [PairTape(t.i.astype(np.intp), t.j.astype(np.intp)) for t in traj.records])
    _, gx, gv = prob.state_cost(traj)
    (ga, a0), (gb, b0) = (backward(prob.integrator, prob.model, t, gx, gv) for t in (traj, wide))
    for a, b in [(ga, gb), (a0.x, b0.x), (a0.v, b0.v)]:
        np.testing.assert_array_equal(a, b)
    big = PairTape.compact(np.array([0, 70000]), np.array([1, 70001]), 70002)
    assert big.i.dtype == np.uint32 and big.j.tolist() == [1, 70001]


def test_the_objective_keeps_no_pair_tapes(monkeypatch):
    prob = small_flock()
    u = 0.3 * np.random.default_rng(1).standard_normal(prob.size)
    seen = []

    def spy(*args, **kwargs):
        seen.append(simulate(*args, **kwargs))
        return seen[-1]
    monkeypatch.setattr(problem_module, "simulate", spy)
    value = prob.objective(u)
    assert len(seen) == 1 and seen[0].records == []
    f = prob.objective_and_gradient(u)[0]
    assert len(seen[1].records) == prob.steps and f == value  # the same value, bit for bit
    with pytest.raises(ValueError, match="kept no per-step records"):
        backward(prob.integrator, prob.model, seen[0], *prob.state_cost(seen[0])[1:])
