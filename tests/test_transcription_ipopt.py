"""The search in positions by IPOPT (``options={"solver": "ipopt"}``): the stretch limit's
constraints and the problem's derivatives against central differences, its Hessian against
the Gauss-Newton matrix it is built from, and the method end to end (the goal and the
physical limit held, a time limit that keeps the best point)."""
import numpy as np
import pytest
import scipy.sparse as sp

import casadi_keyframe as ck
from casadi_keyframe.optimize.finish.constraint import control_hessian
from casadi_keyframe.optimize.outcome import LIMIT
from casadi_keyframe.optimize.positions import Transcription
from casadi_keyframe.optimize.positions.goal import goal_constraints
from casadi_keyframe.optimize.positions.interior import PositionNLP
from casadi_keyframe.optimize.positions.stretch import StretchLimit
from test_transcription import sheet_problem


@pytest.fixture(scope="module")
def nlp():
    prob = sheet_problem(rows=4)
    tr = Transcription(prob)
    return PositionNLP(tr, goal_constraints(tr), control_hessian(prob),
                       StretchLimit(tr, prob.limits.stretch))


def _moved(nlp):
    """A point off the passive motion (every frame moved a little)."""
    z = nlp.tr.unknowns(nlp.tr.base)
    return z + 0.01 * np.random.default_rng(1).standard_normal(z.size)


def _central(f, z, d, h):
    return (f(z + h * d) - f(z - h * d)) / (2 * h)


def test_the_stretch_constraints_are_the_springs_squared_stretch(nlp):
    z = _moved(nlp)
    x = nlp.tr.frames(z)
    springs = nlp.tr.problem.model.springs
    largest = max(nlp.tr.problem.model.max_stretch(frame) for frame in x[1:])
    assert nlp.stretch.stretch(z) == pytest.approx(largest, rel=1e-12)
    assert nlp.stretch.size == springs.i.size * nlp.tr.N  # every spring has a free end here


def test_the_constraints_jacobian_and_hessian_are_their_central_differences(nlp):
    z, d = _moved(nlp), np.random.default_rng(2).standard_normal(nlp.tr.size)
    slope = nlp.jacobian(z) @ d
    for h in (1e-4, 1e-5, 1e-6):
        assert np.allclose(_central(nlp.values, z, d, h), slope, rtol=1e-6, atol=1e-9)
    lam = np.random.default_rng(3).uniform(0, 1, nlp.m)
    hess = nlp.stretch.hessian(lam[len(nlp.goals):]) + sum(
        l * C for l, C in zip(lam, nlp.C))
    turn = hess @ d
    for h in (1e-4, 1e-5, 1e-6):
        assert np.allclose(_central(lambda y: nlp.jacobian(y).T @ lam, z, d, h), turn,
                           rtol=1e-6, atol=1e-8)


def test_the_efforts_gradient_is_its_central_difference_and_the_hessian_its_gauss_newton_matrix(nlp):
    z, d = _moved(nlp), np.random.default_rng(4).standard_normal(nlp.tr.size)
    slope = nlp.point(z)["gradient"] @ d
    for h in (1e-5, 1e-6, 1e-7):
        assert _central(lambda y: nlp.point(y)["effort"], z, d, h) == pytest.approx(
            slope, rel=1e-5)
    lam = np.random.default_rng(5).uniform(0, 1, nlp.m)
    upper = nlp.hessian(z, 2.0, lam)
    full = upper + sp.triu(upper, k=1).T
    p = nlp.point(z)
    expected = (2.0 * (p["J"].T @ nlp.Q @ p["J"] + p["Jr"].T @ p["Jr"])
                + nlp.stretch.hessian(lam[len(nlp.goals):])
                + sum(l * C for l, C in zip(lam, nlp.C)))
    assert abs(full - expected).max() <= 1e-9 * abs(expected).max()


def test_ipopt_holds_the_goal_and_the_stretch_limit_and_its_controls_replay():
    prob = sheet_problem()
    result = ck.solve(prob, method="transcription", maxiter=60,
                      options={"solver": "ipopt"}, quiet=True)
    b = result.breakdown
    assert b["misses"][0]["rms_position_error"] <= 0.01
    assert b["physical"]["max_stretch"] <= prob.limits.stretch
    run = prob.simulate(result.x, records=False)
    assert np.allclose(run.x, result.trajectory.x, rtol=0, atol=1e-12)
    assert "IPOPT iterations in positions" in result.message


def test_a_time_limit_ends_ipopt_with_its_best_point_kept():
    prob = sheet_problem()
    result = ck.solve(prob, method="transcription", maxiter=500, time_limit=1.0,
                      options={"solver": "ipopt"}, quiet=True)
    assert result.status == LIMIT and result.message.startswith("time limit reached")
    assert np.allclose(prob.simulate(result.x, records=False).x, result.trajectory.x,
                       rtol=0, atol=1e-12)


def test_an_unknown_solver_is_refused_with_the_valid_ones():
    with pytest.raises(ValueError, match="sqp, ipopt"):
        ck.solve(sheet_problem(), method="transcription", options={"solver": "snopt"})


def test_the_exact_hessian_is_the_central_difference_of_the_efforts_gradient():
    """``hessian=exact``: the Gauss-Newton matrix plus the forces' and the strain penalty's
    second derivatives (:mod:`.curvature`) is the slope of the gradient (stable over three
    steps), on a sheet whose springs are stretched past the strain limit."""
    from casadi_keyframe.objectives import StrainLimit

    prob = sheet_problem(rows=4)
    prob = ck.ControlProblem(model=prob.model, integrator=prob.integrator, x0=prob.x0,
                             v0=prob.v0, steps=prob.steps, dt=prob.dt, controls=prob.controls,
                             objective=prob.objective_terms + StrainLimit(1.01, 1e3),
                             name="strained")
    tr = Transcription(prob)
    exact = PositionNLP(tr, goal_constraints(tr), control_hessian(prob),
                        StretchLimit(tr, prob.limits.stretch), exact=True)
    z, d = _moved(exact), np.random.default_rng(6).standard_normal(tr.size)
    assert exact.strain.residuals(z, False)[0].size > 0
    upper = exact.hessian(z, 1.0, np.zeros(exact.m))
    turn = (upper + sp.triu(upper, k=1).T) @ d
    gauss_newton = exact.hessian(z, 1.0, np.zeros(exact.m)) - sp.triu(
        exact.curvature(z, exact.point(z)["grad_u"]))
    scale = np.abs(turn).max()
    for h in (1e-6, 1e-7, 1e-8):  # (a larger h crosses the spring law's kink at rest)
        slope = _central(lambda y: exact.point(y)["gradient"], z, d, h)
        assert np.abs(slope - turn).max() <= 1e-7 * scale
    # the second-order part matters here: the Gauss-Newton matrix alone is off by percents
    turn_gn = (gauss_newton + sp.triu(gauss_newton, k=1).T) @ d
    assert np.abs(slope - turn_gn).max() >= 1e-2 * scale


def test_the_exact_hessian_is_ipopts_only():
    with pytest.raises(ValueError, match="give solver=ipopt"):
        ck.solve(sheet_problem(), method="transcription", options={"hessian": "exact"},
                 quiet=True)
