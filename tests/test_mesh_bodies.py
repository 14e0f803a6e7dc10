"""Bodies from triangle meshes: closest features and signs against libigl and the true
sphere, files in (OBJ, PC2 with its rest mesh, USD time samples), and the exact gradient
routes against CasADi and central differences on a small sheet dropped on a small mesh,
still, deforming per frame, and turning with friction."""
import pickle

import numpy as np
import pytest

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.export.obj import write_obj
from casadi_keyframe.export.pc2 import write_pc2
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.meshes import MeshError
from casadi_keyframe.meshes.distance import EDGE, FACE, VERTEX, MeshShape, pieces
from casadi_keyframe.models import ClothModel, Contact, MeshBody
from casadi_keyframe.models.contact.colliders import signed_distances

from helpers import assert_exact_routes, assert_forward_derivative

igl = pytest.importorskip("igl")
trimesh = pytest.importorskip("trimesh")


def ball(subdivisions=2, radius=0.3):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(s.vertices), np.asarray(s.faces)


def near_surface(k, radius=0.3, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(k, 3))
    return d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(0.8, 1.2, k)[:, None] * radius


def test_closest_features_agree_with_libigl_and_the_true_sphere():
    V, F = ball(3)
    x = near_surface(500)
    shape = MeshShape(V, F, pieces(F, len(V)))
    found = shape.closest(x)
    S, _, C, _ = igl.signed_distance(x, V, F.astype(np.int64),
                                     igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)
    np.testing.assert_allclose(found.distance, S, atol=1e-12)
    np.testing.assert_allclose(found.point, C, atol=1e-12)
    assert {FACE, EDGE, VERTEX} <= set(found.kind.tolist())
    body = MeshBody(V, F)
    phi = signed_distances(body, x, 0.0)
    np.testing.assert_allclose(phi, S, atol=1e-12)
    assert np.abs(phi - (np.linalg.norm(x, axis=1) - 0.3)).max() < 2e-3  # the facets' sag


def test_an_open_mesh_signs_by_side_and_pieces_make_a_union():
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]])
    body = MeshBody(square, [[0, 1, 2], [0, 2, 3]])
    x = np.array([[0.3, 0.2, 0.01], [0.3, 0.2, -0.01], [1.5, 0.0, 0.5]])
    np.testing.assert_allclose(signed_distances(body, x, 0.0),
                               [0.01, -0.01, np.hypot(0.5, 0.5)], atol=1e-12)
    V, F = ball(1, 0.2)
    two = MeshBody(np.vstack([V, V + [0.3, 0, 0]]), np.vstack([F, F + len(V)]))
    assert len(two.pieces) == 2
    # inside both balls' overlap: the deepest of the two; outside: the nearer surface
    phi = signed_distances(two, np.array([[0.15, 0, 0], [0.15, 0, 0.5]]), 0.0)
    assert phi[0] < -0.03 and phi[1] > 0.3


def test_a_mesh_body_moves_by_frames_and_by_its_motion():
    V, F = ball(1)
    frames = np.array([V, V + [0, 0, 0.5]])
    body = MeshBody(V, F, frames, fps=2.0)  # rises at 1 m/s for half a second
    x = np.array([[0.0, 0.0, 0.6]])
    rows = body.local_geometry(x, 0.25)
    np.testing.assert_allclose(rows[5], [[0, 0, 1.0]], atol=1e-6)  # the surface's velocity
    spin = lambda t: (np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0],  # noqa
                                [0, 0, 1.0]]), np.array([1.0, 0, 0]))
    turning = MeshBody(V, F, motion=spin)
    point = turning.local_geometry(np.array([[1.0, 0.0, 0.35]]), 0.0)[0]
    np.testing.assert_allclose(turning.local_geometry(np.array([[1.0, 0.0, 0.35]]), 0.0)[5],
                               np.cross([0, 0, 1.0], point - [1.0, 0, 0]), atol=1e-6)
    again = pickle.loads(pickle.dumps(body))  # the trees are rebuilt
    np.testing.assert_array_equal(again.local_geometry(x, 0.3)[0], body.local_geometry(x, 0.3)[0])


def test_mesh_files_in(tmp_path):
    V, F = ball(1)
    obj = write_obj(tmp_path / "ball.obj", V, F)
    still = MeshBody.from_file(obj)
    assert not still.moves and still.faces.shape == F.shape
    write_obj(tmp_path / "walk_rest.obj", V, F)
    write_pc2(tmp_path / "walk.pc2", np.array([V, V + [0, 0, 0.1], V + [0, 0, 0.2]]))
    cached = MeshBody.from_file(tmp_path / "walk.pc2", fps=10.0)
    assert cached.moves
    np.testing.assert_allclose(cached.world_vertices(0.15), V + [0, 0, 0.15], atol=1e-6)
    with pytest.raises(MeshError, match="frames per second"):
        MeshBody.from_file(tmp_path / "walk.pc2")
    with pytest.raises(MeshError, match="rest mesh"):
        MeshBody.from_file(tmp_path / "walk.pc2", rest=tmp_path / "none.obj", fps=10.0)
    Usd = pytest.importorskip("pxr.Usd")
    from pxr import UsdGeom
    stage = Usd.Stage.CreateNew(str(tmp_path / "ball.usda"))
    stage.SetTimeCodesPerSecond(24)
    mesh = UsdGeom.Mesh.Define(stage, "/ball")
    mesh.CreateFaceVertexCountsAttr([3] * len(F))
    mesh.CreateFaceVertexIndicesAttr(F.ravel().tolist())
    for code in (1, 25):
        mesh.GetPointsAttr().Set([tuple(p) for p in V + [0, 0, 0.1 * (code - 1) / 24]], code)
    stage.GetRootLayer().Save()
    sampled = MeshBody.from_file(tmp_path / "ball.usda")
    np.testing.assert_allclose(sampled.times, [0.0, 1.0])
    np.testing.assert_allclose(sampled.world_vertices(0.5), V + [0, 0, 0.05], atol=1e-6)


def test_bad_meshes_and_a_missing_libigl_are_refused(monkeypatch):
    V, F = ball(1)
    with pytest.raises(ValueError, match="faces must be"):
        MeshBody(V, F + len(V))
    with pytest.raises(ValueError, match="need their times"):
        MeshBody(V, F, np.array([V, V]))
    monkeypatch.setitem(__import__("sys").modules, "igl", None)
    with pytest.raises(ImportError, match=r"casadi_keyframe\[bodies\]"):
        MeshBody(V, F)


def sheet_on_mesh(collision, body, steps=6):
    model = ClothModel.grid(4, 4, width=0.6, height=0.6, plane="xy", mass=0.3,
                            colliders=[body], collision=collision)
    x0 = model.rest_positions + [0, 0, 0.012]
    v0 = np.zeros_like(x0)
    v0[:, 0], v0[:, 2] = 0.3, -0.5
    objective = StateKeyframe(steps, x=x0 + [0.1, 0.05, 0.0]) + Smoothness(1e-4)
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=v0, steps=steps, dt=1 / 60, controls=StepForces(),
                          objective=objective)


def small_bodies():
    V, F = ball(1)
    spin = lambda t: (np.array([[np.cos(3 * t), -np.sin(3 * t), 0],  # noqa: E731
                                [np.sin(3 * t), np.cos(3 * t), 0], [0, 0, 1.0]]),
                      np.array([0.3, 0.3, -0.3 + 0.5 * t]))
    frames = np.array([V * (1 + 0.2 * k) + [0.3, 0.3, -0.3 + 0.3 * k] for k in range(4)])
    return {"still": ("guarded", MeshBody(V + [0.3, 0.3, -0.3], F)),
            "frames": ("constraint", MeshBody(V, F, frames, fps=10)),
            "turning, friction": ("guarded", MeshBody(V, F, motion=spin,
                                                      contact=Contact(friction=0.5))),
            "penalty": ("penalty", MeshBody(V + [0.3, 0.3, -0.3], F))}


@pytest.mark.parametrize("case", sorted(small_bodies()))
def test_gradients_on_a_mesh_body_are_exact(case):
    collision, body = small_bodies()[case]
    prob = sheet_on_mesh(collision, body)
    u = 0.002 * np.random.default_rng(0).standard_normal(prob.size)
    traj = prob.simulate(u)
    if collision != "penalty":
        assert any(r.held is not None for r in traj.records)
    kinds = np.concatenate([body.local_geometry(x, k / 60)[3].ravel()
                            for k, x in enumerate(traj.x)])
    assert (kinds == 0).any()  # some particles nearest an edge or a vertex
    g, d = assert_exact_routes(prob, u)
    assert_forward_derivative(prob, u, g @ d, d)


def test_mesh_keyframes_takes_bodies_and_refuses_bad_ones_by_name(tmp_path):
    from casadi_keyframe.loading import OverrideError, load_problem
    V, F = ball(1, 0.2)
    obj = write_obj(tmp_path / "ball.obj", V + [0.3, 0.0, -0.6], F)
    prob = load_problem("mesh_keyframes", bodies=str(obj), guess="none")
    assert any(isinstance(b, MeshBody) for b in prob.model.colliders)
    assert prob.simulate(prob.initial_controls()).x.shape[0] == prob.steps + 1
    (tmp_path / "empty.obj").write_bytes(b"")
    for bad, why in ((tmp_path / "none.obj", "no such file"), (tmp_path / "empty.obj", "no mesh"),
                     (tmp_path / "walk.pc2", "rest mesh")):
        with pytest.raises(OverrideError, match=f"mesh_keyframes: bodies: .*{why}"):
            load_problem("mesh_keyframes", bodies=str(bad))


def test_the_character_as_a_mesh_follows_its_capsules(tmp_path):
    from casadi_keyframe.scenes.animations import walk
    from casadi_keyframe.scenes.body_meshes import character_body, write_body
    from casadi_keyframe.scenes.skeleton import Character
    character = Character()
    motion = walk(character)
    body = character_body(character, motion, 0.1, 1 / 60)
    assert len(body.parts()) == len(character.radii)  # one piece per capsule, held apart
    rng = np.random.default_rng(0)
    x = body.world_vertices(0.05)[rng.integers(0, len(body.vertices), 300)]
    x = x + rng.normal(scale=0.02, size=x.shape)
    exact = character.clearance(motion.pose(0.05), x)
    assert np.abs(signed_distances(body, x, 0.05) - exact).max() < 2e-3  # the facets' sag
    again = MeshBody.from_file(write_body(tmp_path / "walk.pc2", body, 0.1, 1 / 60), fps=60)
    np.testing.assert_allclose(again.world_vertices(0.05), body.world_vertices(0.05),
                               atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("rising", [False, True])
def test_a_sheet_dropped_on_an_icosphere_file_stays_on_the_true_sphere(rising):
    """The issue's icosphere check (benchmarks/contact.py --only mesh prints it whole): within
    5 mm of the true sphere, springs under 1.3; the centre of mass follows the analytic
    sphere's run within 1 cm through the impact, after which the draping sheet parts from
    it by about as much as from a sphere 0.3 mm smaller (the facets' sag)."""
    from casadi_keyframe.scenes.drops import mesh_drop
    r = mesh_drop(25, 8.0, rising=rising)
    assert r["mesh"]["inside"] <= 0.005 and r["mesh"]["stretch"] <= 1.3
    gap = np.linalg.norm(r["mesh"]["com"] - r["sphere"]["com"], axis=1)
    assert gap[:5].max() <= 0.01 and gap.max() <= 0.07


def test_a_still_mesh_builds_its_tree_once_and_spares_far_points_with_the_same_result(
        monkeypatch):
    """A still mesh's AABB tree is built once for the whole run, its queries at a step's
    t and t + dt and the next step's start are one, and points beyond every law's reach get
    a stand-in instead of the tree's query: the run is bit for bit the exact one."""
    from casadi_keyframe.meshes import distance
    from casadi_keyframe.models.contact.colliders import Body
    from casadi_keyframe.scenes.drops import drop_model, drop_start
    from casadi_keyframe.simulate import simulate

    V, F = ball(2)
    built, asked = [], []
    shape, closest = distance.MeshShape.__init__, distance.MeshShape.closest
    monkeypatch.setattr(distance.MeshShape, "__init__",
                        lambda self, *a: built.append(1) or shape(self, *a))
    monkeypatch.setattr(distance.MeshShape, "closest", lambda self, p, near=None, bounds=None: (
        asked.append(len(p) if near is None else int(near.sum())) or closest(self, p, near,
                                                                            bounds)))

    def run():
        model = drop_model(8, MeshBody(V + [0.5, 0.5, -0.3], F), "guarded")
        x0, v0 = drop_start(model, 4.0)
        return simulate(LinearizedBackwardEuler("direct"), model, x0, v0,
                        np.zeros((12, model.n, 3)), 1 / 60)

    spared = run()
    assert len(built) == 1
    spared_points, asked[:] = sum(asked), []
    monkeypatch.setattr(Body, "reach", lambda self, v, t, dt: None)
    exact = run()
    np.testing.assert_array_equal(spared.x, exact.x)
    assert spared_points < 0.8 * sum(asked)  # the tree was asked for fewer points
