"""Coulomb friction through the hold and bodies that move and turn: a sheet on a slope stays
or slides as Coulomb says, a thrown sheet stops where it should, bodies moving and turning
into a falling sheet leave it whole, and the gradient routes agree on sliding and sticking
scenes."""
import numpy as np
import pytest

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import (Capsule, ClothModel, ClothParams, Contact, Coulomb, Plane,
                                    Sphere)
from casadi_keyframe.simulate import simulate

from helpers import assert_exact_routes, assert_forward_derivative

G = 9.81


def sheet_on(ground, collision, rows=6):
    return ClothModel.grid(rows, rows, width=0.5, height=0.5, plane="xy", mass=0.3,
                           colliders=[ground], collision=collision,
                           params=ClothParams(air_drag=0.0))


def resting(model, ground, normal, angle=0.0):
    """The sheet lying on ``ground`` at rest: on the layer (the hold's), or as deep in the
    penalty springs' layer as its weight sinks it."""
    c = ground.contact
    sink = 0.0
    if model.collision == "guarded":
        sink = np.sqrt(2 * c.width * model.masses.max() * G * np.cos(angle) / c.stiffness)
    x = model.rest_positions - model.rest_positions.mean(0)
    turn = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)],
                     [0, np.sin(angle), np.cos(angle)]])
    return x @ turn.T + normal * (c.thickness - sink)


@pytest.mark.parametrize("collision", ["constraint", "guarded"])
@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_a_sheet_on_a_slope_stays_or_slides_as_coulomb_says(collision, mu):
    angle = np.radians(20)
    normal = np.array([0, -np.sin(angle), np.cos(angle)])
    ground = Plane((0, 0, 0), normal, contact=Contact(friction=mu))
    model = sheet_on(ground, collision)
    x0 = resting(model, ground, normal, angle)
    traj = simulate(LinearizedBackwardEuler(), model, x0, np.zeros_like(x0),
                    np.zeros((60, model.n, 3)), 1 / 60)
    down = np.array([0, -np.cos(angle), -np.sin(angle)])
    slid = (traj.x[-1] - traj.x[0]).mean(0) @ down
    expected = max(0.0, G * (np.sin(angle) - mu * np.cos(angle))) / 2
    if expected == 0:
        assert abs(slid) < 1e-3
    else:
        assert slid == pytest.approx(expected, rel=0.1)


@pytest.mark.parametrize("collision", ["constraint", "guarded"])
def test_a_sheet_thrown_along_the_ground_stops_after_v2_over_2_mu_g(collision):
    mu, speed = 0.3, 3.0
    ground = Plane((0, 0, 0), contact=Contact(friction=mu))
    model = sheet_on(ground, collision)
    x0 = resting(model, ground, np.array([0, 0, 1.0]))
    v0 = np.zeros_like(x0)
    v0[:, 0] = speed
    steps = int(60 * (speed / (mu * G) + 0.2))
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((steps, model.n, 3)),
                    1 / 60)
    assert np.abs(traj.v[-1]).max() < 1e-6  # stopped and stuck
    travelled = traj.x[-1, :, 0].mean() - x0[:, 0].mean()
    assert travelled == pytest.approx(speed ** 2 / (2 * mu * G), rel=0.1)


def test_a_sticking_particle_moves_with_a_turning_body():
    """On a turntable (a plane spinning about z) a sheet that sticks turns with it."""
    w = 2.0
    spin = lambda t: (np.array([[np.cos(w * t), -np.sin(w * t), 0],  # noqa: E731
                                [np.sin(w * t), np.cos(w * t), 0], [0, 0, 1.0]]), np.zeros(3))
    table = Plane((0, 0, 0), contact=Contact(friction=5.0), motion=spin)
    model = sheet_on(table, "constraint")
    x0 = resting(model, table, np.array([0, 0, 1.0])) + [0.3, 0, 0]
    v0 = np.cross([0, 0, w], x0) * [1, 1, 0]
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((30, model.n, 3)),
                    1 / 60)
    angle = np.arctan2(*traj.x[-1].mean(0)[[1, 0]]) - np.arctan2(*x0.mean(0)[[1, 0]])
    assert angle == pytest.approx(w * 0.5, rel=0.05)
    # the stick follows the surface's velocity, not its step's rigid displacement: the
    # sheet drifts out by (w dt)^2 / 2 of its radius per step
    assert model.max_stretch(traj.x[-1]) < 1.1


def test_the_surface_velocity_includes_the_rotation():
    w = np.array([0.0, 0.0, 3.0])
    spin = lambda t: (np.array([[np.cos(3 * t), -np.sin(3 * t), 0],  # noqa: E731
                                [np.sin(3 * t), np.cos(3 * t), 0], [0, 0, 1.0]]),
                      np.array([0.0, 0.0, 0.5 * t]))
    ball = Sphere((0.1, 0, 0), 0.3, motion=spin)
    centre, _, velocity, omega = ball.geometry(0.2)
    np.testing.assert_allclose(omega, w, atol=1e-6)
    np.testing.assert_allclose(velocity, np.cross(w, centre) + [0, 0, 0.5], atol=1e-6)
    rod = Capsule(lambda t: np.zeros(3), lambda t: [np.cos(t), np.sin(t), 0.0], 0.1)
    *_, omega = rod.geometry(0.4)
    np.testing.assert_allclose(omega, [0, 0, 1.0], atol=1e-6)


MOVING = {"rising sphere": (lambda: Sphere(lambda t: [0.5, 0.5, -0.25 + 2 * t], 0.25), 4.0),
          "rising capsule": (lambda: Capsule(lambda t: [0.2, 0.5, -0.08 + 2 * t],
                                             lambda t: [0.8, 0.5, -0.08 + 2 * t], 0.08), 2.0),
          "swinging capsule": (lambda: Capsule(
              [0.2, 0.5, -0.08], lambda t: [0.2 + 0.6 * np.cos(3 * t), 0.5,
                                            -0.08 + 0.6 * np.sin(3 * t)], 0.08), 0.0)}


@pytest.mark.parametrize("case", sorted(MOVING))
def test_a_body_moving_into_a_falling_sheet_leaves_it_whole(case):
    make, speed = MOVING[case]
    model = ClothModel.grid(12, 12, plane="xy", mass=0.3, colliders=[make()])
    x0 = model.rest_positions + [0, 0, 0.03]
    v0 = np.tile([0.0, 0.0, -speed], (model.n, 1))
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((18, model.n, 3)),
                    1 / 60)
    report = model.physical_report(traj.x, 1 / 60)
    assert report["max_penetration"] <= 0.005 and report["max_stretch"] <= 1.3, report


def sliding_problem(collision, steps, body="plane"):
    if body == "plane":
        ground = Plane((0, 0, 0), (0, -0.2, 1), contact=Contact(friction=0.4))
    else:
        spin = lambda t: (np.array([[np.cos(3 * t), -np.sin(3 * t), 0],  # noqa: E731
                                    [np.sin(3 * t), np.cos(3 * t), 0], [0, 0, 1.0]]),
                          np.array([0.3, 0.3, -0.3 + 0.5 * t]))
        ground = Sphere((0, 0, 0), 0.3, contact=Contact(friction=0.5), motion=spin)
    model = ClothModel.grid(4, 4, width=0.6, height=0.6, plane="xy", mass=0.3,
                            colliders=[ground], collision=collision)
    x0 = model.rest_positions + [0, 0, 0.012]
    v0 = np.zeros_like(x0)
    v0[:, 0], v0[:5, 0], v0[:, 2] = 1.0, 0.1, -0.3
    objective = StateKeyframe(steps, x=x0 + [0.1, 0.05, 0.0]) + Smoothness(1e-4)
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=v0, steps=steps, dt=1 / 60, controls=StepForces(),
                          objective=objective)


@pytest.mark.parametrize("collision, steps, body", [("constraint", 2, "plane"),
                                                    ("guarded", 6, "sphere")])
def test_gradients_through_sticking_and_sliding_are_exact(collision, steps, body):
    prob = sliding_problem(collision, steps, body)
    u = 0.002 * np.random.default_rng(0).standard_normal(prob.size)
    held = [r.held for r in prob.simulate(u).records if r.held is not None]
    assert any((~h.stick).any() for h in held)  # some particle slides
    g, d = assert_exact_routes(prob, u)
    assert_forward_derivative(prob, u, g @ d, d)


SMALL = {"cloth_arch": {"rows": 3, "cols": 3, "steps": 2},
         "cloth_toss": {"rows": 3, "cols": 3, "steps": 4},
         "cape_blend": {"rows": 6, "cols": 4, "steps": 4, "guess": "passive"}}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_set_friction_reaches_every_body_of_the_problems_that_have_bodies(name):
    from casadi_keyframe.cli.values import parse_overrides
    from casadi_keyframe.loading import OverrideError, load_problem
    plain = load_problem(name, **SMALL[name]).model
    assert all(b.contact.friction == 0 for b in plain.colliders)  # frictionless by default
    model = load_problem(name, **SMALL[name], **parse_overrides(["friction=0.4"])).model
    hold = model.family("body hold")
    assert model.colliders and all(b.contact.friction == 0.4 for b in model.colliders)
    assert [b.law for b in hold.bodies] == [Coulomb(0.4)] * len(model.colliders)
    assert hold.stick_slide is not None
    with pytest.raises(OverrideError, match="friction"):
        load_problem(name, **SMALL[name], friction=-0.1)
