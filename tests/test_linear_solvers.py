"""The linear solver objects: modified PCG against sparse LU, with and without constrained
components, transpose solves, the statistics they report, and their refusals."""
import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from casadi_keyframe.linear import (Auto, ModifiedPCG, SolveError, SparseCholesky, SparseLU,
                                    System, cholmod_available, linear_solver)

needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="cvxopt is not installed")


def spd(n, seed=0):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=0.05, random_state=seed)
    return (B @ B.T + sp.diags(rng.uniform(1, 2, n))).tocsr()


def mask(n, pinned):
    free = np.ones(n, bool)
    free[:pinned] = False
    return free


@pytest.mark.parametrize("pinned", [0, 7])
def test_cg_equals_direct_solve(pinned):
    A = spd(120)
    b = np.random.default_rng(1).standard_normal(120)
    free = mask(120, pinned)
    z = np.where(free, 0.0, 0.3)
    x_cg, info = ModifiedPCG(tol=1e-12).init(free).factor(A).solve(b, z)
    x_lu, lu_info = SparseLU().init(free).factor(A).solve(b, z)
    np.testing.assert_allclose(x_cg, x_lu, rtol=1e-9, atol=1e-10)
    assert info.iterations > 0 and info.residual <= 1e-12 and np.all(x_cg[~free] == 0.3)
    assert lu_info.iterations == 0 and lu_info.residual < 1e-12
    residual = (A @ x_cg - b)[free]
    assert np.linalg.norm(residual) < 1e-9 * np.linalg.norm(b)


@pytest.mark.parametrize("pinned", [0, 5])
def test_a_factorisation_solves_the_transposed_system(pinned):
    """Sparse LU of a non-symmetric A solves ``A^T x = b`` with the same factors, the
    constrained part moved to the right-hand side through ``A^T``."""
    n = 60
    A = (spd(n) + 0.3 * sp.random(n, n, density=0.05, random_state=4)).tocsr()
    free = mask(n, pinned)
    b = np.random.default_rng(5).standard_normal(n)
    z = np.where(free, 0.0, -0.2)
    x, info = SparseLU(symmetric=False).init(free).factor(A).solve_transpose(b, z)
    assert np.abs((A.T @ x - b)[free]).max() < 1e-12 and np.all(x[~free] == -0.2)
    assert info.residual < 1e-12
    y, _ = SparseLU(symmetric=False).init(free).factor(A).solve(b, z)
    assert np.abs((A @ y - b)[free]).max() < 1e-12 and np.abs(x - y).max() > 1e-3


def test_cg_reports_failure_to_converge():
    A = spd(200)
    with pytest.raises(SolveError, match="did not converge"):
        ModifiedPCG(tol=1e-14, maxiter=2).init(np.ones(200, bool)).factor(A).solve(np.ones(200))


def test_cg_refuses_an_indefinite_matrix():
    A = sp.diags([1.0, -2.0, 3.0]).tocsr()
    with pytest.raises(SolveError, match="not positive definite"):
        ModifiedPCG().init(np.ones(3, bool)).factor(A)


def test_direct_solve_reports_a_singular_matrix():
    A = sp.diags([1.0, 0.0, 3.0]).tocsr()
    with pytest.raises(SolveError, match="singular"):
        SparseLU().init(np.ones(3, bool)).factor(A)


@needs_cholmod
@pytest.mark.parametrize("pinned", [0, 7])
def test_cholesky_equals_lu_and_keeps_what_it_is_asked_to(pinned):
    A, n = spd(120), 120
    free, b = mask(n, pinned), np.random.default_rng(1).standard_normal(n)
    z = np.where(free, 0.0, 0.3)
    plan = SparseCholesky().init(free)
    kept = plan.factor(A, keep=True)
    x, info = kept.solve(b, z)
    x_lu, _ = SparseLU().init(free).factor(A).solve(b, z)
    np.testing.assert_allclose(x, x_lu, rtol=1e-10, atol=1e-12)
    assert info.iterations == 0 and np.all(x[~free] == 0.3)
    pattern = object()  # what a fixed-pattern assembly passes: one key per structure
    system = dataclasses.replace(System.from_matrix(A, free), structure=pattern)
    twice = dataclasses.replace(System.from_matrix(2 * A, free), structure=pattern)
    shared = plan.factor(system)
    np.testing.assert_allclose(shared.solve(b, z)[0], x, rtol=1e-10)
    plan.factor(twice)  # the pattern's shared analysis now holds 2 A
    with pytest.raises(RuntimeError, match="overwritten"):
        shared.solve(b)
    again = plan.factor(system)
    indefinite = dataclasses.replace(System.from_matrix(-A, free), structure=pattern)
    with pytest.raises(SolveError, match="not positive definite"):
        plan.factor(indefinite)
    with pytest.raises(RuntimeError, match="overwritten"):  # the failed one spoilt it too
        again.solve(b)
    np.testing.assert_allclose(kept.solve_transpose(b, z)[0], x, rtol=1e-12)  # still A
    assert kept.nbytes > 0


@needs_cholmod
def test_a_released_factor_goes_back_to_the_pool():
    A, free = spd(60), np.ones(60, bool)
    plan = SparseCholesky().init(free)
    system = dataclasses.replace(System.from_matrix(A, free), structure=object())
    first = plan.factor(system, keep=True)
    made = plan.analyses
    b = np.ones(60)
    x = first.solve(b)[0]
    first.release()
    assert not first.usable
    with pytest.raises(RuntimeError, match="released"):
        first.solve(b)
    second = plan.factor(system, keep=True)  # the released analysis, refactorised
    assert plan.analyses == made and second.usable
    np.testing.assert_allclose(second.solve(b)[0], x, rtol=1e-12)


@needs_cholmod
def test_the_default_path_analyses_a_cloth_pattern_once_across_gradients():
    """Under solver="auto" a cloth's step pattern is analysed by the first gradient only: the
    forward pass keeps one factor per step, the backward pass solves with them and releases
    them, and the next gradient refactorises the same analyses numerically."""
    from casadi_keyframe.integrators import LinearizedBackwardEuler
    from casadi_keyframe.scenes.sheets import hanging_sheet, swing_problem
    prob = swing_problem(hanging_sheet(6), 10, 1 / 60, LinearizedBackwardEuler())
    u = 0.01 * np.random.default_rng(0).standard_normal(prob.size)
    plan = prob.integrator.plan(prob.model)
    counts = []
    for route in ("adjoint", "adjoint", "swapped", "swapped", "adjoint"):
        before = plan.analyses
        prob.objective_and_gradient(u, route)
        counts.append(plan.analyses - before)
    # one per kept step, one to size the factors; the swapped route's last step (no step
    # after it kept a factor) factors once more, in the shared analysis
    assert counts == [prob.steps + 1, 0, 1, 0, 0]
    assert prob.integrator.plan(prob.model) is plan


@needs_cholmod
def test_cholesky_refuses_an_indefinite_matrix():
    with pytest.raises(SolveError, match="not positive definite"):
        SparseCholesky().init(np.ones(3, bool)).factor(sp.diags([1.0, -2.0, 3.0]))


def test_symmetric_lu_does_not_pivot_off_the_diagonal():
    """An SPD cloth-like matrix (not diagonally dominant): SuperLU's symmetric mode with
    threshold 0 keeps its row order equal to its column order, so the fill stays that of a
    Cholesky factor."""
    from casadi_keyframe.integrators.linearized_backward_euler import step_matrices
    from casadi_keyframe.models import ClothModel
    model = ClothModel.grid(12, 12, pinned=[0, 11])
    x = model.rest_positions * [1.0, 0.9, 1.0]  # compressed: not diagonally dominant
    A, _ = step_matrices(model, x, np.zeros_like(x), 1 / 30)
    factors = SparseLU().init(model.free_mask()).factor(A)
    assert np.array_equal(factors.lu.perm_r, factors.lu.perm_c)
    pivoting = SparseLU(symmetric=False).init(model.free_mask()).factor(A)
    assert factors.lu.nnz < pivoting.lu.nnz


def test_auto_chooses_by_size_and_what_is_installed():
    auto = Auto(cholmod_max=100, lu_max=200)
    small = SparseCholesky if cholmod_available() else SparseLU
    assert isinstance(auto.choose(50), small)
    assert isinstance(auto.choose(150), SparseLU)
    assert isinstance(auto.choose(300), ModifiedPCG)
    assert isinstance(auto.init(np.ones(300, bool)).solver, ModifiedPCG)


def test_solvers_by_name_and_bad_names():
    assert isinstance(linear_solver("cg", tol=1e-6), ModifiedPCG)
    assert isinstance(linear_solver("direct"), SparseLU)
    assert isinstance(linear_solver("auto"), Auto)
    with pytest.raises(ValueError, match="solver must be one of"):
        linear_solver("lu")
    with pytest.raises(TypeError, match="init"):
        linear_solver(3.0)
