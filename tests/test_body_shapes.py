"""Bodies reach pictures and exports as typed shapes (geometry.py): each shape says its
extent and polygons, so a new shape is drawn in pictures, the viewer and USD without a
line changed in render/ or export/; the shapes' polygons are the ones drawn before."""
from dataclasses import dataclass

import numpy as np
import pytest

from casadi_keyframe import ControlProblem, StateKeyframe, StepForces
from casadi_keyframe.export import export_scene, scene_of
from casadi_keyframe.geometry import (BodyShape, Patch, Round, TriangleMesh, capsule_grid,
                                      grid_triangles, moves)
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel, Plane, Sphere
from casadi_keyframe.render import snapshot


@dataclass(frozen=True, eq=False)
class Cube(BodyShape):
    """An axis-aligned cube of half-side ``half`` about ``center``: six quads."""

    center: np.ndarray
    half: float

    def extent(self, mid=None):
        return self.center + self.half * np.array([[-1, -1, -1], [1, 1, 1.0]])

    def polygons(self, mid=None, half=None, detail: int = 8):
        corners = self.center + self.half * np.array(
            [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        faces = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6],
                          [0, 2, 6, 4], [1, 5, 7, 3]])
        return corners, faces


class Boxy(Sphere):
    """A sphere for contact, drawn as the cube around it: a collider with a new shape."""

    def shape(self, t):
        center, radius, *_ = self._floats(t)
        return Cube(center, float(radius[0]))


def test_each_shape_gives_its_polygons():
    patch = Patch(np.zeros(3), np.array([0, 0, 1.0]))
    vertices, faces = patch.triangles(np.array([0, 0, 1.0]), 0.5)
    np.testing.assert_allclose(vertices[:, 2], 0.0)
    np.testing.assert_allclose(np.abs(vertices[:, :2]), 0.5)
    assert faces.tolist() == [[0, 1, 2], [0, 2, 3]] and patch.beneath
    np.testing.assert_allclose(patch.extent(np.array([0.3, 0.2, 4.0])), [[0.3, 0.2, 0.0]])
    a, b = np.zeros(3), np.array([1.0, 0, 0])
    capsule = Round(a, b, 0.1)
    vertices, quads = capsule.polygons(detail=5)
    grid = capsule_grid(a, b, 0.1, 5)
    np.testing.assert_array_equal(vertices[quads], np.stack(
        [grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]], axis=2).reshape(-1, 4, 3))
    assert capsule.triangles(detail=5)[1].tolist() == grid_triangles(10, 10).tolist()
    assert not capsule.sphere and Round(a, a, 0.1).sphere
    mesh = TriangleMesh(vertices, grid_triangles(10, 10))
    assert mesh.triangles()[0] is vertices and not mesh.beneath


def test_shapes_say_whether_a_body_moves():
    still = Plane((0, 0, -1.0))
    rolling = Sphere(lambda t: np.array([t, 0.0, 0.0]), 0.2)
    times = [0.0, 0.1, 0.2]
    assert not moves([still.shape(t) for t in times])
    assert moves([rolling.shape(t) for t in times])
    assert not rolling.shape(0.0).same(still.shape(0.0))


@pytest.fixture(scope="module")
def cube_scene():
    model = ClothModel.grid(4, 4, pinned=[0, 3], colliders=[Boxy((0.5, 0.5, -0.6), 0.2),
                                                            Plane((0, 0, -1.0))])
    x0 = model.rest_positions
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler(), x0=x0,
                          v0=np.zeros_like(x0), steps=3, dt=1 / 30, controls=StepForces(),
                          objective=StateKeyframe(3, x=x0), name="cube")
    return prob, prob.simulate(prob.initial_controls())


def test_a_new_shape_is_drawn_in_pictures(cube_scene, tmp_path):
    prob, traj = cube_scene
    assert snapshot(prob, traj, tmp_path / "cube.png").stat().st_size > 0


def test_a_new_shape_is_written_to_usd_and_the_viewer(cube_scene, tmp_path):
    pytest.importorskip("pxr", reason="usd-core is not installed: pip install casadi_keyframe[usd]")
    from pxr import Usd, UsdGeom

    prob, traj = cube_scene
    scene = scene_of(prob, traj)
    [path] = export_scene(scene, "usd", tmp_path)
    stage = Usd.Stage.Open(str(path))
    cube = UsdGeom.Mesh(stage.GetPrimAtPath("/Result/Colliders/Boxy0"))
    assert len(cube.GetPointsAttr().Get()) == 8
    assert list(cube.GetFaceVertexCountsAttr().Get()) == [4] * 6
    pytest.importorskip("plotly", reason="plotly is not installed")
    [page] = export_scene(scene, "html", tmp_path)
    assert page.stat().st_size > 0
