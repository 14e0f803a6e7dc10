"""Cloth rendering: render.animate / render.snapshot hand a cloth over to render.cloth (3-D)."""
import numpy as np
import pytest
from PIL import Image

from casadi_keyframe import (CenterOfMassKeyframe, ControlProblem, ParticleKeyframe, StateKeyframe,
                             StepForces, render)
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.contact.colliders import Capsule, Plane, Sphere
from casadi_keyframe.render import cloth as render_cloth
from casadi_keyframe.views import ClothView, Ring

STEPS = 6


def _problem(colliders=None, view=None, objective=None):
    """A 4 x 4 sheet lying flat, pinned at one corner, above a sphere, a capsule and a floor."""
    if colliders is None:
        colliders = [Sphere((0.5, 0.5, -0.4), 0.3), Plane((0, 0, -1.0)),
                     Capsule((0, 0, -0.5), (1, 0, -0.5), 0.1)]
    model = ClothModel.grid(4, 4, plane="xy", colliders=colliders, pinned=[0])
    x0 = model.rest_positions
    if objective is None:
        objective = (StateKeyframe(STEPS, x=x0 + [0, 0, -0.2])
                     + CenterOfMassKeyframe(3, x=x0.mean(0)))
    if view is None:
        view = ClothView(ring=Ring(center=(0.5, 0.5, -0.5), normal=(0, 0, 1), radius=0.2))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(), x0=x0,
                          v0=np.zeros_like(x0), steps=STEPS, dt=1 / 30, controls=StepForces(),
                          objective=objective, name="cloth-render", view=view)


@pytest.fixture(scope="module")
def cloth():
    p = _problem()
    return p, p.simulate()


def test_animate_writes_gif(cloth, tmp_path):
    p, traj = cloth
    out = render.animate(p, traj, tmp_path / "cloth.gif", fps=10, title="custom")
    assert out == tmp_path / "cloth.gif" and out.stat().st_size > 0
    with Image.open(out) as im:
        assert im.n_frames == STEPS + 1


def test_animate_subsamples_keeping_keyframes(cloth, tmp_path):
    p, traj = cloth
    out = render.animate(p, traj, tmp_path / "few.gif", max_frames=3)
    with Image.open(out) as im:
        assert im.n_frames == len(render.select_frames(STEPS, render.keyframes(p), 3))


def test_snapshot_writes_png(cloth, tmp_path):
    p, traj = cloth
    for out in (render.snapshot(p, traj, tmp_path / "snap.png"),
                render.snapshot(p, traj, tmp_path / "one.png", frames=[2])):
        assert out.stat().st_size > 0
        with Image.open(out) as im:
            assert im.format == "PNG"
    with pytest.raises(ValueError):
        render.snapshot(p, traj, tmp_path / "bad.png", frames=[0, STEPS + 1])


def test_face_colors_finite_and_shaded(cloth):
    p, traj = cloth
    faces = p.model.faces
    for x in traj.x:
        rgba = render_cloth.face_colors(x, faces)
        assert rgba.shape == (len(faces), 4) and np.all(np.isfinite(rgba))
        assert np.all((rgba >= 0) & (rgba <= 1))
    flat = render_cloth.face_colors(traj.x[0], faces)
    flipped = render_cloth.face_colors(traj.x[0], faces[:, ::-1])
    np.testing.assert_allclose(flat, flipped)  # both sides lit alike
    degenerate = render_cloth.face_colors(np.zeros((3, 3)), [[0, 1, 2]])
    assert np.all(np.isfinite(degenerate))


def test_moving_sphere_and_other_terms(tmp_path):
    """A sphere moving with t, a single-particle keyframe, no ring, a custom camera."""
    model_terms = ParticleKeyframe(4, [15], x=[[1.0, 1.0, -0.3]])
    p = _problem(colliders=[Sphere(lambda t: (0.5, 0.5 - t, -0.4), 0.3)],
                 view=ClothView(camera=(35, -120)),
                 objective=model_terms + CenterOfMassKeyframe(STEPS, v=[0, 0, 0]))
    traj = p.simulate()
    assert render.snapshot(p, traj, tmp_path / "moving.png").stat().st_size > 0
    with Image.open(render.animate(p, traj, tmp_path / "moving.gif", max_frames=2)) as im:
        assert im.n_frames == len(render.select_frames(STEPS, render.keyframes(p), 2))


def test_limits_hold_cloth_colliders_and_ring(cloth):
    p, traj = cloth
    box = render_cloth.Box.of(p, traj)
    inside = [traj.x.reshape(-1, 3), [[0.5, 0.5, -0.7], [0.5, 0.5, -0.1]],  # sphere
              [[-0.1, 0, -0.5], [1.1, 0, -0.5]], [[0.7, 0.5, -0.5]], [[0.5, 0.5, -1.0]]]
    for pts in inside:
        assert np.all(np.asarray(pts) >= box.lo) and np.all(np.asarray(pts) <= box.hi)
