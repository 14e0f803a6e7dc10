"""Export (issue 15): each format read back reproduces result.npz at every frame to float32
precision, with the frame rate of dt; USD passes USD's own checks; bad input is refused."""
import sys

import numpy as np
import pytest

from casadi_keyframe import cli, load_problem
from casadi_keyframe.export import export, export_scene, scene_of
from casadi_keyframe.export.obj import read_obj
from casadi_keyframe.export.pc2 import MAGIC, read_pc2


def _solve(tmp_path_factory, name, *sets):
    out = tmp_path_factory.mktemp(name)
    args = ["solve", name, *[a for s in sets for a in ("--set", s)], "--maxiter", "1",
            "--quiet", "--no-animation", "--no-viewer", "--out", str(out)]
    assert cli.main(args) in (0, 3)
    return out, np.load(out / "result.npz")


@pytest.fixture(scope="module")
def cloth(tmp_path_factory):
    return _solve(tmp_path_factory, "cloth_toss", "rows=4", "cols=5", "steps=10")


@pytest.fixture(scope="module")
def flock(tmp_path_factory):
    return _solve(tmp_path_factory, "flock_race", "agents=8", "steps=12")


def test_pc2_and_rest_obj_round_trip(cloth):
    out, result = cloth
    pc2, rest = export(out, "pc2")
    assert (pc2.name, rest.name) == ("cloth_toss.pc2", "cloth_toss_rest.obj")
    assert pc2.read_bytes()[:12] == MAGIC
    positions, start, rate = read_pc2(pc2)
    np.testing.assert_array_equal(positions, result["x"].astype(np.float32))  # every frame
    assert (start, rate) == (0.0, 1.0)  # one sample per frame from frame 0
    vertices, faces = read_obj(rest)
    np.testing.assert_array_equal(vertices, result["x"][0].astype(np.float32))
    model = load_problem("cloth_toss", rows=4, cols=5, steps=10).model
    np.testing.assert_array_equal(faces, model.faces)


def test_obj_sequence_round_trip(cloth, tmp_path):
    out, result = cloth
    paths = export(out, "obj", out=tmp_path)
    assert len(paths) == result["x"].shape[0] and paths[0].parent == tmp_path / "obj"
    for n, path in enumerate(paths):
        vertices, faces = read_obj(path)
        np.testing.assert_array_equal(vertices, result["x"][n].astype(np.float32))
        assert faces.shape[1] == 3 and faces.min() == 0


def test_a_2d_flock_lies_in_z_0(flock, tmp_path):
    out, result = flock
    positions, _, _ = read_pc2(export(out, "pc2", out=tmp_path)[0])
    np.testing.assert_array_equal(positions[..., :2], result["x"].astype(np.float32))
    assert not positions[..., 2].any()
    assert read_obj(tmp_path / "flock_race_rest.obj")[1].size == 0  # agents, no faces


def _stage(path):
    pxr = pytest.importorskip("pxr", reason="usd-core is not installed: pip install "
                                            "casadi_keyframe[usd]")
    from pxr import Usd
    assert pxr
    return Usd.Stage.Open(str(path))


def test_usd_cloth_round_trip_and_compliance(cloth):
    pytest.importorskip("pxr", reason="usd-core is not installed: pip install casadi_keyframe[usd]")
    from pxr import UsdGeom

    from casadi_keyframe.export.usd import validate

    out, result = cloth
    (path,) = export(out, "usd")
    stage, dt = _stage(path), float(result["dt"])
    assert stage.GetTimeCodesPerSecond() * dt == pytest.approx(1.0, rel=1e-12)
    assert stage.GetFramesPerSecond() * dt == pytest.approx(1.0, rel=1e-12)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, result["x"].shape[0] - 1)
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Result/Cloth"))
    points = mesh.GetPointsAttr()
    assert points.GetTimeSamples() == list(range(result["x"].shape[0]))
    for n, x in enumerate(result["x"]):
        np.testing.assert_array_equal(np.array(points.Get(n)), x.astype(np.float32))
    assert set(mesh.GetFaceVertexCountsAttr().Get()) == {3}
    children = {p.GetName() for p in stage.GetPrimAtPath("/Result/Targets").GetChildren()}
    terms = load_problem("cloth_toss", rows=4, cols=5, steps=10).objective_terms.terms
    frames = [term.frame for term in terms if hasattr(term, "frame")]
    assert children == {f"CenterOfMass_{frames[0]}", f"ParticleKeyframe_{frames[1]}", "Ring"}
    assert stage.GetPrimAtPath("/Result/Colliders/Plane0").IsValid()
    assert validate(path) == []


def test_usd_flock_point_instancer(flock, tmp_path):
    pytest.importorskip("pxr", reason="usd-core is not installed: pip install casadi_keyframe[usd]")
    from pxr import Gf, UsdGeom

    out, result = flock
    stage = _stage(export(out, "usd", out=tmp_path)[0])
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Result/Flock"))
    assert list(inst.GetIdsAttr().Get()) == list(range(8))
    protos = [str(p) for p in inst.GetPrototypesRel().GetTargets()]
    assert protos == ["/Result/Flock/Prototypes/Agent", "/Result/Flock/Prototypes/Highlighted"]
    assert UsdGeom.Cone(stage.GetPrimAtPath(protos[0])).GetAxisAttr().Get() == "X"
    highlight = load_problem("flock_race", agents=8, steps=12).view.highlight
    index = list(inst.GetProtoIndicesAttr().Get())
    assert [i for i, k in enumerate(index) if k == 1] == list(highlight) and set(index) == {0, 1}
    for n in (0, 5, result["x"].shape[0] - 1):
        np.testing.assert_array_equal(np.array(inst.GetPositionsAttr().Get(n))[:, :2],
                                      result["x"][n].astype(np.float32))
        np.testing.assert_array_equal(np.array(inst.GetVelocitiesAttr().Get(n))[:, :2],
                                      result["v"][n].astype(np.float32))
        # a reader's instance transforms: each cone's +x along its agent's velocity
        for m, v in zip(inst.ComputeInstanceTransformsAtTime(n, n), result["v"][n]):
            heading = Gf.Matrix4d(m).TransformDir(Gf.Vec3d(1, 0, 0))
            np.testing.assert_allclose(heading, np.r_[v, 0] / np.linalg.norm(v), atol=2e-3)
    assert len(inst.ComputeInstanceTransformsAtTime(5, 5)) == 8


def test_heading_quaternions_turn_x_onto_the_velocity():
    from scipy.spatial.transform import Rotation

    from casadi_keyframe.export.usd import heading_quaternions
    v = np.array([[1.0, 0, 0], [0, 2, 0], [0, 0, -3], [-1, 0, 0], [0, 0, 0], [1, -2, 0.5]])
    q = heading_quaternions(v)
    turned = Rotation.from_quat(q[:, [1, 2, 3, 0]]).apply([1.0, 0, 0])  # scipy: real last
    np.testing.assert_allclose(turned[[0, 1, 2, 3, 5]],
                               v[[0, 1, 2, 3, 5]] / np.linalg.norm(v[[0, 1, 2, 3, 5]], axis=1,
                                                                   keepdims=True), atol=1e-12)
    np.testing.assert_allclose(q[4], [1, 0, 0, 0])


def test_usd_blend_has_its_clips_and_moving_capsules(tmp_path):
    pytest.importorskip("pxr", reason="usd-core is not installed: pip install casadi_keyframe[usd]")
    from pxr import UsdGeom

    from casadi_keyframe.export.usd import validate

    p = load_problem("cape_blend", rows=6, cols=5, window=0.2, guess="passive")
    traj = p.simulate(records=False)
    (path,) = export_scene(scene_of(p, traj), "usd", tmp_path)
    stage = _stage(path)
    a = round(p.view.t_a / p.dt)
    fall = UsdGeom.Mesh(stage.GetPrimAtPath("/Result/Clips/fall/Cape")).GetPointsAttr()
    np.testing.assert_array_equal(np.array(fall.Get(3)),
                                  p.view.fall.trajectory.x[a + 3].astype(np.float32))
    capsules = [q for q in stage.Traverse() if q.IsA(UsdGeom.Capsule)]
    assert capsules and any(UsdGeom.Xformable(q).TransformMightBeTimeVarying() for q in capsules)
    assert validate(path) == []


def test_bad_input_is_refused_with_the_fix(cloth, tmp_path, monkeypatch, capsys):
    out, _ = cloth
    assert cli.main(["export", str(tmp_path / "none"), "--format", "obj"]) == 2
    assert "neither a results folder" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        cli.main(["export", str(out), "--format", "fbx"])
    assert stop.value.code == 2
    with pytest.raises(ValueError, match="usd, pc2, obj, html"):
        export(out, "fbx")
    monkeypatch.setitem(sys.modules, "pxr", None)  # as if usd-core were not installed
    assert cli.main(["export", str(out), "--format", "usd", "--out", str(tmp_path)]) == 2
    assert "pip install casadi_keyframe[usd]" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing half-written
