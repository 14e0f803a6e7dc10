"""Smooth control metrics: S is symmetric, keeps constants and is undone by unsmooth; the
search in z sees the same objective and the gradient S g; a smoothed solve runs and reports
in u; the refusals."""
import numpy as np
import pytest

from casadi_keyframe import InitialVelocity, StepForces, load_problem, solve
from casadi_keyframe.optimize.metrics import mesh_laplacian, search_metric
from casadi_keyframe.models import ClothModel
from casadi_keyframe.optimize.evaluator import MetricView


def toss(**controls):
    prob = load_problem("cloth_toss", rows=5, cols=5, steps=12)
    return prob.with_controls(InitialVelocity(**controls))


def shapes(**controls):
    prob = load_problem("cloth_shapes", rows=4, cols=4, steps=12)
    agents = prob.controls.agents
    return prob.with_controls(StepForces(agents=agents, **controls))


@pytest.mark.parametrize("build, options", [
    (toss, {"smoothing": 0.3}),
    (shapes, {"smoothing": 0.3, "time_smoothing": 0.05}),
    (shapes, {"time_smoothing": 0.05})])
def test_the_metric_is_symmetric_keeps_constants_and_inverts(build, options):
    prob = build(**options)
    metric = search_metric(prob)
    rng = np.random.default_rng(0)
    z, y = rng.standard_normal((2, prob.size))
    assert np.dot(metric.smooth(z), y) == pytest.approx(np.dot(z, metric.smooth(y)), rel=1e-12)
    np.testing.assert_allclose(metric.unsmooth(metric.smooth(z)), z, atol=1e-12)
    constant = np.ones(prob.size)
    np.testing.assert_allclose(metric.smooth(constant), constant, atol=1e-12)
    rough = metric.smooth(z)
    assert np.linalg.norm(rough) < np.linalg.norm(z)  # high frequencies damped


def test_the_search_in_z_sees_the_same_objective_and_the_smoothed_gradient():
    prob = shapes(smoothing=0.3, time_smoothing=0.05)
    metric = search_metric(prob)

    def ev(u):
        return prob.objective_and_gradient(u)

    ev.interrupted, ev.best_u = None, None
    seen = MetricView(ev, metric)
    z = 0.01 * np.random.default_rng(1).standard_normal(prob.size)
    f, g = seen(z)
    assert f == pytest.approx(prob.objective(metric.smooth(z)), rel=1e-12)
    d = np.random.default_rng(2).standard_normal(prob.size)
    h = 1e-6
    fd = (seen(z + h * d)[0] - seen(z - h * d)[0]) / (2 * h)
    assert np.dot(g, d) == pytest.approx(fd, rel=1e-5)


def test_a_smoothed_solve_lowers_the_objective_and_reports_controls():
    prob = shapes(smoothing=0.3, time_smoothing=0.05)
    result = solve(prob, maxiter=8, quiet=True)
    assert result.fun < prob.objective(prob.initial_controls())
    assert result.x.size == prob.size
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-10)


def test_the_mesh_laplacian_weighs_edges_by_their_length():
    model = ClothModel.grid(3, 3, width=2.0, height=1.0)
    L = mesh_laplacian(model.faces, model.rest_positions, np.arange(9)).toarray()
    np.testing.assert_allclose(L.sum(axis=1), 0, atol=1e-12)
    assert L[0, 1] == pytest.approx(-1.0)  # 1 m along the width
    assert L[0, 3] == pytest.approx(-4.0)  # 0.5 m along the height


def test_refusals():
    with pytest.raises(ValueError, match="positive length"):
        StepForces(smoothing=-1.0)
    with pytest.raises(ValueError, match="bounds or smoothing"):
        StepForces(smoothing=0.2, upper=1.0)
    with pytest.raises(ValueError, match="controls per step"):
        toss(time_smoothing=0.1)
    flock = load_problem("flock_path", agents=5, steps=20)
    flock = flock.with_controls(StepForces(smoothing=0.5))
    with pytest.raises(ValueError, match="needs a mesh"):
        search_metric(flock)
