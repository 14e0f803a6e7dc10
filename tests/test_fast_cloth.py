"""The fast cloth step: step matrices gathered from blocks into a fixed pattern that grows
with self-contact, every linear solver on the same trajectory and gradients as modified
PCG, and the factors the forward pass keeps for the derivative passes."""
import numpy as np
import pytest

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.integrators.linearized_backward_euler import step_matrices
from casadi_keyframe.linear import cholmod_available
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.blocks import GrowingPattern
from casadi_keyframe.models import Attachment
from casadi_keyframe.models.contact.colliders import Capsule, Contact, Sphere
from casadi_keyframe.objectives import CenterOfMassKeyframe

SOLVERS = ["direct", "auto"] + (["cholmod"] if cholmod_available() else [])


def busy_sheet():
    """6 x 6 sheet, 1 m: a sphere rising into it, a capsule whose end moves, one corner
    pinned, one led along a path, and self-contact thick enough (0.46 m) that unjoined
    neighbours two rows apart touch at rest and more pairs touch as it folds."""
    bodies = [Sphere(lambda t: np.array([0.5, 0.5, -0.33 + 0.4 * t]), 0.3),
              Capsule((0.0, 0.1, -0.1), lambda t: np.array([1.0, 0.2 + t, -0.06]), 0.05)]
    return ClothModel.grid(6, 6, plane="xy", colliders=bodies, pinned=[5],
                           self_contact=Contact(200.0, 0.5, 0.46, 0.1),
                           attachments=[Attachment([0], lambda t: np.array([[0, 0.3 * t, 0]]))])


def busy_problem(solver="cg", **options):
    model = busy_sheet()
    x0 = model.rest_positions
    objective = (StateKeyframe(12, x=x0 + [0.1, 0, -0.2], v=0 * x0)
                 + CenterOfMassKeyframe(6, x=x0.mean(0)) + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(solver, **options),
                          x0=x0, v0=np.zeros_like(x0), steps=12, dt=1 / 30,
                          controls=StepForces(), objective=objective)


@pytest.fixture(scope="module")
def controls():
    return 0.1 * np.random.default_rng(0).standard_normal(busy_problem().size)


@pytest.fixture(scope="module")
def reference(controls):
    """CG to 1e-13: trajectory, swapped and exact gradients."""
    prob = busy_problem("cg", tol=1e-13, adjoint_tol=1e-13)
    return (prob.simulate(controls),
            *(prob.objective_and_gradient(controls, r)[1] for r in ("swapped", "adjoint")))


def test_the_busy_sheet_meets_new_self_contacts(controls):
    prob = busy_problem("direct")
    traj = prob.simulate(controls)
    work = prob.integrator.init(prob.model)
    found = [prob.model.interactions(x) for x in traj.x]
    pairs = [prob.model.family("self-contact").find(x) for x in traj.x]
    assert all(p[0].size for p in pairs)
    keys = [set(zip(*p)) for p in pairs]
    assert any(b - a for a, b in zip(keys, keys[1:]))  # pairs appear during the run
    for x, v, f in zip(traj.x, traj.v, found):
        prob.integrator.step_system(prob.model, x, v, 0.0, prob.dt, work, interactions=f)
    assert 1 <= work.pattern.growths < len(pairs)


@pytest.mark.parametrize("solver", SOLVERS)
def test_every_solver_follows_cg(solver, controls, reference):
    traj_cg, swapped_cg, exact_cg = reference
    prob = busy_problem(solver)
    traj = prob.simulate(controls)
    scale = np.abs(traj_cg.x).max()
    assert np.abs(traj.x - traj_cg.x).max() < 1e-8 * scale  # contacts amplify roundoff
    for route, g_cg in (("swapped", swapped_cg), ("adjoint", exact_cg)):
        g = prob.objective_and_gradient(controls, route)[1]
        # the stiff contacts amplify roundoff: CG at its default tolerances is 2e-7 away
        assert np.linalg.norm(g - g_cg) < 1e-6 * np.linalg.norm(g_cg), route


def test_cg_keeps_nothing(controls):
    """Keeping CG's prepared matrix would save one assembly per derivative step, next to
    hundreds of iterations: not worth its memory."""
    assert all(r.factor is None for r in busy_problem("cg").simulate(controls).records)


@pytest.mark.parametrize("solver", SOLVERS)
def test_kept_factors_change_no_gradient(solver, controls):
    """The derivative passes give the same numbers whether they reuse the forward pass's
    factorisations or make their own (max_factor_memory=0 keeps none)."""
    kept, none = busy_problem(solver), busy_problem(solver, max_factor_memory=0)
    assert all(r.factor is not None for r in kept.simulate(controls).records)
    assert all(r.factor is None for r in none.simulate(controls).records)
    assert not any(r.factor for r in kept.simulate(controls, records=False).records)
    for route in ("swapped", "adjoint"):
        a = kept.objective_and_gradient(controls, route)[1]
        b = none.objective_and_gradient(controls, route)[1]
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12 * np.abs(b).max())
    tangent = kept.directional_derivative(controls, controls)
    assert np.isclose(tangent, none.directional_derivative(controls, controls), rtol=1e-9)


def test_a_budget_keeps_the_first_factors_only(controls):
    prob = busy_problem("direct")
    one = prob.integrator.init(prob.model).plan
    step = prob.simulate(controls).records[0].factor.nbytes
    assert step > 0 and one is not None
    prob = busy_problem("direct", max_factor_memory=3.5 * step)
    kept = [r.factor is not None for r in prob.simulate(controls).records]
    assert kept[:2] == [True, True] and not any(kept[4:])


def test_the_gathered_step_matrix_is_the_assembled_one(controls):
    """The free block gathered from blocks into the grown pattern equals the free block of
    ``M - dt D - dt^2 K`` assembled from the sparse Jacobians; the blocks' products equal
    the sparse matrices' (df/dx is not symmetric: its transpose too)."""
    prob = busy_problem("direct")
    model, dt = prob.model, prob.dt
    traj = prob.simulate(controls)
    x, v, t = traj.x[9], traj.v[9], 0.3
    contacts = model.interactions(x)
    work = prob.integrator.init(model)
    system = prob.integrator.step_system(model, x, v, t, dt, work, True, contacts)
    A, K, J = system.matrix, system.K, system.df_dx
    A_full, K_full, J_full = step_matrices(model, x, v, dt, t, True, contacts)
    free = np.flatnonzero(model.free_mask())
    expected = A_full[free][:, free].toarray()
    np.testing.assert_allclose(A.free_block.toarray(), expected, atol=1e-12 * abs(expected).max())
    y = np.random.default_rng(2).standard_normal((model.n, 3))
    np.testing.assert_allclose(K.matvec(y).ravel(), K_full @ y.ravel(), atol=1e-10)
    np.testing.assert_allclose(J.matvec(y, transpose=True).ravel(), J_full.T @ y.ravel(),
                               atol=1e-10)
    np.testing.assert_allclose(A.matvec(y.ravel()), A_full @ y.ravel(), atol=1e-10)


def test_a_pattern_grows_only_for_new_pairs():
    model = busy_sheet()
    x, v = model.rest_positions, np.zeros((model.n, 3))
    grown = GrowingPattern(model.step_pattern)
    contacts = model.interactions(x)
    blocks = model.jacobian_blocks(x, v, 0.0, interactions=contacts)[0]
    grown.values(blocks)
    first = grown.pattern
    grown.values(blocks)
    assert grown.growths == 1 and grown.pattern is first
    k = model.families.index(model.family("self-contact"))
    i, j = contacts[k]
    fewer = contacts[:k] + ((i[:1], j[:1]),) + contacts[k + 1:]
    without = model.jacobian_blocks(x, v, 0.0, interactions=fewer)
    grown.values(without[0])  # fewer pairs: the pattern stays
    assert grown.growths == 1 and grown.pattern is first
