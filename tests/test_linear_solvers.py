"""Modified PCG against a direct solve, with and without constrained components."""
import numpy as np
import pytest
import scipy.sparse as sp

from casadi_keyframe.integrators.linear_solvers import SolveError, direct_solve, modified_pcg


def spd(n, seed=0):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=0.05, random_state=seed)
    return (B @ B.T + sp.diags(rng.uniform(1, 2, n))).tocsr()


@pytest.mark.parametrize("pinned", [0, 7])
def test_cg_equals_direct_solve(pinned):
    A = spd(120)
    b = np.random.default_rng(1).standard_normal(120)
    free = np.ones(120, bool)
    free[:pinned] = False
    z = np.where(free, 0.0, 0.3)
    x_cg, it = modified_pcg(A, b, free, z, tol=1e-12)
    x_lu, _ = direct_solve(A, b, free, z)
    np.testing.assert_allclose(x_cg, x_lu, rtol=1e-9, atol=1e-10)
    assert it > 0 and np.all(x_cg[~free] == 0.3)
    residual = (A @ x_cg - b)[free]
    assert np.linalg.norm(residual) < 1e-9 * np.linalg.norm(b)


def test_cg_reports_failure_to_converge():
    A = spd(200)
    with pytest.raises(SolveError, match="did not converge"):
        modified_pcg(A, np.ones(200), np.ones(200, bool), tol=1e-14, maxiter=2)


def test_cg_refuses_an_indefinite_matrix():
    A = sp.diags([1.0, -2.0, 3.0]).tocsr()
    with pytest.raises(SolveError, match="not positive definite"):
        modified_pcg(A, np.ones(3), np.ones(3, bool))


def test_direct_solve_reports_a_singular_matrix():
    A = sp.diags([1.0, 0.0, 3.0]).tocsr()
    with pytest.raises(SolveError, match="singular"):
        direct_solve(A, np.ones(3), np.ones(3, bool))
