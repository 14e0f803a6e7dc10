"""The search in positions' iterative step solve (``positions/linear_solve.py``): its
operator against the formed matrix, its preconditioned conjugate gradients against the
direct factorisation, the search with it against the direct one, and its option."""
import numpy as np
import pytest
import scipy.sparse as sp

import casadi_keyframe as ck
from casadi_keyframe import ControlProblem, StrainLimit
from casadi_keyframe.controls import StepForces
from casadi_keyframe.optimize.finish.constraint import control_hessian
from casadi_keyframe.optimize.positions import Transcription
from casadi_keyframe.optimize.positions import linear_solve as ls
from casadi_keyframe.optimize.positions.goal import goal_constraints
from casadi_keyframe.optimize.positions.sqp import PositionSQP

from test_transcription import STEPS, sheet_problem


def strained_sheet():
    """The 5 x 5 sheet with a strain penalty that acts (its residuals' rows in the matrix)."""
    prob = sheet_problem()
    return ControlProblem(model=prob.model, integrator=prob.integrator, x0=prob.x0,
                          v0=prob.v0, steps=STEPS, dt=prob.dt, controls=StepForces(),
                          objective=prob.objective_terms + StrainLimit(1.01, 1e3),
                          name="strained")


@pytest.fixture(scope="module")
def moved():
    """A search on the strained sheet, its point at a moved plan (springs past the strain
    limit), multipliers that weigh the constraints' Hessians, and a damping."""
    prob = strained_sheet()
    tr = Transcription(prob)
    solver = PositionSQP(tr, goal_constraints(tr), control_hessian(prob),
                         ls.LinearChoice("direct"))
    rng = np.random.default_rng(3)
    x = prob.simulate(0.02 * rng.standard_normal(prob.size), records=False).x
    x[1:] *= 1.05
    point = solver.point(tr.unknowns(x))
    assert point.Jr.shape[0] > 0  # the strain penalty acts here
    return solver, point, np.array([0.7]), 0.3


def test_the_operator_is_the_formed_step_matrix_times_a_vector(moved):
    solver, x, lam, mu = moved
    solve, curvature, _ = solver._system(x, lam, mu)  # the direct path's formed matrix
    op = ls.StepOperator(x.J, solver.Q, x.Jr, zip(lam, solver.C), mu, solver.metric)
    p = np.random.default_rng(4).standard_normal(x.z.size)
    formed = curvature(p)
    assert np.allclose(op.model(p), formed, rtol=1e-12, atol=1e-12 * np.abs(formed).max())
    full = formed + mu * (solver.metric @ p)
    assert np.allclose(op(p), full, rtol=1e-12, atol=1e-12 * np.abs(full).max())
    assert np.allclose(op.diagonal(), op.formed().diagonal(), rtol=1e-12)


@pytest.mark.parametrize("preconditioner", ("steps", "frames", "jacobi"))
def test_conjugate_gradients_solve_as_the_direct_factor_to_their_tolerance(moved,
                                                                           preconditioner):
    solver, x, lam, mu = moved
    solve, _, _ = solver._system(x, lam, mu)
    rhs = np.column_stack([x.gradient, solver._gradients(x.z)])
    direct = solve(rhs)
    choice = ls.LinearChoice("iterative", tol=1e-7, maxiter=3000, settle=0.0,
                             preconditioner=preconditioner)
    system = ls.iterative_system(solver, x, lam, mu, choice)
    found = system.solve(rhs)
    assert system.solves.iterations[0] < 3000
    B = system.operator.formed()
    assert np.linalg.norm(B @ found - rhs) <= 1e-7 * np.linalg.norm(rhs) * 1.01
    cond = np.linalg.cond(B.toarray())
    assert np.linalg.norm(found - direct) <= 1e-7 * cond * np.linalg.norm(direct)


def test_a_stalled_model_stops_conjugate_gradients_early_with_a_model_decrease(moved):
    """Stopped on the model's progress, the solve is inexact, but it lowers the model."""
    solver, x, lam, mu = moved
    op = ls.StepOperator(x.J, solver.Q, x.Jr, zip(lam, solver.C), mu, solver.metric)
    g = x.gradient
    exact, its_exact = ls.conjugate_gradients(op, g, tol=1e-12, maxiter=5000)
    rough, its_rough = ls.conjugate_gradients(op, g, tol=1e-12, maxiter=5000, settle=1e-2)
    model = lambda p: 0.5 * p @ op(p) - g @ p  # noqa: E731
    assert its_rough < its_exact
    assert model(exact) <= model(rough) < 0.9 * model(exact)


def test_the_search_with_the_iterative_solve_meets_the_goal_as_the_direct_one():
    prob = sheet_problem()
    results = {linear: ck.solve(prob, method="transcription", maxiter=25,
                                options={"start": "blend", "linear": linear}, quiet=True)
               for linear in ("direct", "iterative")}
    for result in results.values():
        assert result.breakdown["misses"][0]["rms_position_error"] <= 0.01
        run = prob.simulate(result.x, records=False)
        assert np.allclose(run.x, result.trajectory.x, rtol=0, atol=1e-12)
    cost = {k: prob.control_cost(r.x)[0] for k, r in results.items()}
    assert cost["iterative"] == pytest.approx(cost["direct"], rel=0.2)


def test_auto_chooses_by_size_and_a_bad_value_is_refused_by_name():
    mesh12, sheet16, sheet20 = (34_080, 426), (60_960, 762), (95_520, 1_194)  # 80 frames
    assert not ls.LinearChoice("auto").iterative(*mesh12)
    assert not ls.LinearChoice("auto").iterative(*sheet16)
    assert ls.LinearChoice("auto").iterative(*sheet20)
    assert ls.LinearChoice("iterative").iterative(10, 1)
    assert not ls.LinearChoice("direct").iterative(10 ** 9, 10 ** 4)
    with pytest.raises(ValueError, match="linear"):
        ck.solve(sheet_problem(), method="transcription", options={"linear": "cg"})
    with pytest.raises(ValueError, match="preconditioner"):
        ls.LinearChoice("iterative", preconditioner="ilu")


def test_the_iterative_solve_never_forms_the_step_matrix(monkeypatch):
    """No product of the Jacobians is formed on the iterative path (the direct path's
    pattern and factor are never made)."""
    prob = sheet_problem()
    tr = Transcription(prob)
    solver = PositionSQP(tr, goal_constraints(tr), control_hessian(prob),
                         ls.LinearChoice("iterative"))
    monkeypatch.setattr(solver, "_pattern", lambda x: pytest.fail("the pattern was formed"))
    monkeypatch.setattr(solver, "factor", lambda B: pytest.fail("a factor was made"))
    outcome, _ = solver.run(tr.unknowns(prob.simulate(None, records=False).x), maxiter=3,
                            tol=1e-12)
    assert outcome.iterations == 3 and solver.solves.iterations


def test_conjugate_gradients_stop_at_a_pending_signal(monkeypatch):
    from casadi_keyframe.interrupts import Interrupted
    calls = []

    def pending():
        calls.append(1)
        if len(calls) > 2:
            raise Interrupted()

    monkeypatch.setattr(ls, "check", pending)
    A = sp.diags(np.linspace(1.0, 1e4, 200)).tocsr()
    with pytest.raises(Interrupted):
        ls.conjugate_gradients(lambda p: A @ p, np.ones(200), tol=1e-14)
    assert len(calls) == 3
