"""The objective as residuals (a Gauss-Newton search's view): every term's value is 0.5 |r|^2,
and the whole map's products J p (tangent pass) and J^T w (backward pass) agree with central
differences of r, with each other (the dot test) and with the adjoint gradient (J^T r), on a
flock, a cloth holding contact with a body and a mesh keyframe problem."""
import numpy as np
import pytest
from helpers import small_flock

from casadi_keyframe import (CenterOfMassKeyframe, ControlProblem, InitialVelocity, Smoothness,
                             StateKeyframe, StepForces, StrainLimit)
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.meshes import check_mesh
from casadi_keyframe.models import ClothModel
from casadi_keyframe.objectives import MeshKeyframe, RegionTarget
from casadi_keyframe.optimize.residual.linearization import linearize
from casadi_keyframe.scenes.cloths import cloth_problem
from casadi_keyframe.scenes.drops import drop_model, drop_start
from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, wave
from casadi_keyframe.shapes import Disc


def held_contact(steps=6):
    """A 4 x 4 sheet thrown onto a sphere, held by the guarded contact (steps revised), with
    a keyframe, a centre keyframe, a region, a strain limit that acts and smooth effort."""
    model = drop_model(4, "sphere", "guarded")
    x0, v0 = drop_start(model, 6.0, gap=0.02)
    objective = (StateKeyframe(steps, x=x0 + [0, 0, -0.05], v=np.zeros_like(x0),
                               velocity_weight=0.1)
                 + CenterOfMassKeyframe(3, x=x0.mean(0) + [0.05, 0, 0], v=[0, 0, -1.0])
                 + RegionTarget(4, Disc((0.2, 0.2), 0.1), weight=3.0)
                 + StrainLimit(1.0001, 50.0) + Smoothness(1e-4, temporal=1e-5))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=v0, steps=steps, dt=1 / 60, controls=StepForces(),
                          objective=objective, name="held")


def mesh_problem(align=False, steps=8):
    vertices, quads = hanging_sheet(4, 4, 0.5)
    model = ClothModel.from_file(check_mesh(vertices, quads), pinned=[0, 3])
    weights = np.linspace(0.5, 1.5, model.n)
    objective = (MeshKeyframe(4, wave(vertices, 0.2), weight=30.0, vertex_weights=weights,
                              align=align)
                 + MeshKeyframe(steps, fold(vertices), weight=10.0, align=align)
                 + StrainLimit(1.0001, 20.0) + Smoothness(1e-3, temporal=1e-4))
    return cloth_problem(model=model, steps=steps, dt=1 / 60, objective=objective, name="mesh")


PROBLEMS = {"flock": lambda: small_flock(),
            "flock velocities": lambda: small_flock(controls=InitialVelocity()),
            "held contact": held_contact, "mesh": mesh_problem,
            "mesh aligned": lambda: mesh_problem(align=True)}


def point(prob, seed=0):
    scale = 0.3 if prob.model.dim == 2 else 0.01
    return scale * np.random.default_rng(seed).standard_normal(prob.size)


@pytest.mark.parametrize("name", PROBLEMS)
def test_every_term_is_half_its_squared_residual(name):
    prob = PROBLEMS[name]()
    u = point(prob)
    traj = prob.simulate(u)
    for term in prob.objective_terms.state_terms + prob.objective_terms.trajectory_terms:
        r = term.residual(traj)
        assert 0.5 * r @ r == pytest.approx(term.value(traj), rel=1e-12, abs=1e-300), term
    for term in prob.objective_terms.control_terms:
        r = term.residual(u, prob.controls, prob.dt)
        assert 0.5 * r @ r == pytest.approx(prob.control_cost(u)[0], rel=1e-12)
    lin = linearize(prob, u)
    assert lin.value == pytest.approx(prob.objective(u), rel=1e-12)
    if name == "held contact":
        assert any(r.held is not None for r in lin.trajectory.records)
    for term in prob.objective_terms.trajectory_terms:  # the strain limit acts somewhere
        assert np.count_nonzero(term.residual(traj)) > 0


@pytest.mark.parametrize("name", PROBLEMS)
def test_jacobian_products_agree_with_differences_each_other_and_the_gradient(name):
    prob = PROBLEMS[name]()
    rng = np.random.default_rng(1)
    u = point(prob)
    lin = linearize(prob, u)
    p, w = rng.standard_normal(prob.size), rng.standard_normal(lin.shape[0])
    jp, jtw = lin.jvp(p), lin.vjp(w)
    assert w @ jp == pytest.approx(jtw @ p, rel=1e-10)  # the dot test
    g = prob.objective_and_gradient(u, "adjoint")[1]
    assert np.linalg.norm(lin.gradient() - g) <= 1e-10 * np.linalg.norm(g)
    h = 1e-6 if prob.model.dim == 2 else 1e-7
    central = (linearize(prob, u + h * p).residual
               - linearize(prob, u - h * p).residual) / (2 * h)
    if name == "mesh aligned":  # Kaufman's Jacobian: off by a term of the residual's size
        assert np.linalg.norm(central - jp) <= 0.05 * np.linalg.norm(central)
    else:
        assert np.linalg.norm(central - jp) <= 1e-6 * np.linalg.norm(central)
    lin.release()


def test_the_aligned_jacobian_is_exact_where_the_shape_is_met():
    """Where the cloth takes the target's shape (moved and turned), the aligned residual's
    Kaufman Jacobian is its exact derivative."""
    prob = mesh_problem(align=True, steps=4)
    traj = prob.simulate(point(prob))
    term = prob.objective_terms.state_terms[0]
    turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    x = traj.x.copy()
    x[term.frame] = term.position_target @ turn.T + [0.1, 0.2, 0.3]
    at = type(traj)(x, traj.v, traj.dt)
    assert np.linalg.norm(term.residual(at)) < 1e-12
    d = np.random.default_rng(2).standard_normal(x.shape)
    h = 1e-6
    moved = [type(traj)(x + s * h * d, traj.v, traj.dt) for s in (1, -1)]
    central = (term.residual(moved[0]) - term.residual(moved[1])) / (2 * h)
    assert np.linalg.norm(central - term.residual_jvp(at, d, 0 * d)) <= 1e-6 * np.linalg.norm(
        central)
