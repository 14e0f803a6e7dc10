"""Pins that move (mesh_keyframes' ``pin_motion`` and ``pin_body``): the pinned vertices
follow a time-sampled mesh of the cloth, or ride on a body, at every frame; every bad input
is refused naming the option (exit 2); the gradient through moving pins is the forward
pass's derivative (the hand adjoint, CasADi's reverse mode and central differences)."""
import numpy as np
import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.export.obj import write_obj
from casadi_keyframe.export.pc2 import write_pc2
from casadi_keyframe.loading import load_problem
from casadi_keyframe.export.pc2 import read_pc2
from casadi_keyframe.scenes.mesh_targets import hanging_sheet, write_carried_sheet

from helpers import assert_forward_derivative

FRAMES = 20
TOP = "0,1,2,3"  # the top row of a 4 x 4 sheet


@pytest.fixture(scope="module")
def carried(tmp_path_factory):
    """A 4 x 4 sheet, its top row carried 0.2 m sideways over FRAMES frames, the wave carried
    as far; and a 5 x 5 sheet's motion (another vertex count)."""
    folder = tmp_path_factory.mktemp("carried")
    paths = write_carried_sheet(folder, 4, 4, FRAMES, shift=(0.2, 0.0, 0.0))
    other = write_carried_sheet(folder / "five", 5, 5, FRAMES)
    return {**{k: str(v) for k, v in paths.items()}, "five": str(other["motion"]),
            "folder": folder}


def problem(files, **more):
    sets = {"cloth": files["sheet"], "keyframes": f"{FRAMES}:{files['wave']}",
            "pins": tuple(int(i) for i in TOP.split(",")), "pin_motion": files["motion"],
            "guess": "none", **more}
    return load_problem("mesh_keyframes", **sets)


def test_the_pins_follow_the_file_at_every_frame(carried):
    prob = problem(carried)
    assert prob.model.attachments and not prob.model.pinned.size
    u = np.random.default_rng(0).normal(scale=0.05, size=prob.size)
    traj = prob.simulate(u)
    frames = read_pc2(carried["motion"])[0]
    pins = [int(i) for i in TOP.split(",")]
    assert np.abs(traj.x[:, pins] - frames[:, pins]).max() <= 1e-12
    # the velocities are the ones the positions imply: the step is consistent
    np.testing.assert_allclose(traj.v[1:, pins], np.diff(frames[:, pins], axis=0) / prob.dt,
                               atol=1e-9)
    assert np.ptp(traj.x[:, 5, 0]) > 0.01  # the free vertices are simulated, and follow


def test_a_solve_hits_the_keyframe_with_pins_that_follow(carried, tmp_path, capsys):
    out = tmp_path / "run"
    args = ["solve", "mesh_keyframes", "--set", f"cloth={carried['sheet']}",
            "--set", f"keyframes={FRAMES}:{carried['wave']}", "--set", f"pins={TOP}",
            "--set", f"pin_motion={carried['motion']}", "--out", str(out), "--quiet",
            "--no-animation", "--no-viewer"]
    assert main(args) == 0, capsys.readouterr()
    saved = np.load(out / "result.npz")
    replay = problem(carried, guess="aim").simulate(saved["u"])  # replayed by simulate
    pins = [int(i) for i in TOP.split(",")]
    frames = read_pc2(carried["motion"])[0]
    assert np.abs(replay.x[:, pins] - frames[:, pins]).max() <= 1e-6
    assert np.array_equal(replay.x, saved["x"])


def test_more_frames_are_cut_with_a_note_and_a_far_start_is_noted(carried, capsys):
    prob = problem(carried, steps=FRAMES - 4, keyframes=f"{FRAMES - 4}:{carried['wave']}")
    assert prob.steps == FRAMES - 4
    assert f"the first {FRAMES - 3} (0..{FRAMES - 4}) are used" in capsys.readouterr().err
    vertices, quads = hanging_sheet(4, 4)
    moved = np.repeat(vertices[None] + [0, 0, 0.01], FRAMES + 1, axis=0)
    write_obj(carried["folder"] / "lifted_rest.obj", vertices, quads)
    write_pc2(carried["folder"] / "lifted.pc2", moved)
    prob = problem(carried, pin_motion=str(carried["folder"] / "lifted.pc2"))
    assert "up to 10 mm from the cloth file's vertices" in capsys.readouterr().err
    assert np.allclose(prob.x0[0], vertices[0] + [0, 0, 0.01])


def write_changing_usd(path, vertices, quads, frames):
    """A USD mesh of ``vertices`` whose last time sample drops a face."""
    Usd = pytest.importorskip("pxr.Usd")
    from pxr import UsdGeom
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(60)
    mesh = UsdGeom.Mesh.Define(stage, "/cloth")
    for code in range(frames + 1):
        kept = quads if code < frames else quads[:-1]
        mesh.GetFaceVertexCountsAttr().Set([4] * len(kept), code)
        mesh.GetFaceVertexIndicesAttr().Set(np.ravel(kept).tolist(), code)
        mesh.GetPointsAttr().Set([tuple(p) for p in vertices], code)
    stage.GetRootLayer().Save()
    return path


@pytest.mark.parametrize("case, option, words", [
    ("vertices", "pin_motion", "has 25 vertices per frame, the cloth 16"),
    ("frames", "pin_motion", f"has {FRAMES + 1} frames (0..{FRAMES}), the run needs "
                             f"{FRAMES + 6}"),
    ("still", "pin_motion", "does not move: give a time-sampled mesh"),
    ("topology", "pin_motion", "topology changes over time"),
    ("both", "pin_body", "and pin_motion both move the pins"),
    ("index", "pin_body", "3 is no body: bodies gives 1"),
    ("name", "pin_body", "'arm': no body"),
    ("no bodies", "pin_body", "which gives none"),
    ("no pins", "pin_motion", "none is pinned"),
])
def test_bad_input_exits_2_naming_the_option(carried, capsys, case, option, words):
    vertices, quads = hanging_sheet(4, 4)
    changing = carried["folder"] / "changing.usda"
    if case == "topology" and not changing.exists():
        write_changing_usd(changing, vertices, quads, FRAMES)
    sets = {"vertices": [f"pin_motion={carried['five']}"],
            "frames": [f"pin_motion={carried['motion']}", f"steps={FRAMES + 5}",
                       f"keyframes={FRAMES + 5}:{carried['wave']}"],
            "still": [f"pin_motion={carried['rest']}"],
            "topology": [f"pin_motion={changing}"],
            "both": [f"pin_motion={carried['motion']}", f"bodies={carried['rest']}",
                     "pin_body=0"],
            "index": [f"bodies={carried['rest']}", "pin_body=3"],
            "name": [f"bodies={carried['rest']}", "pin_body=arm"],
            "no bodies": ["pin_body=0"],
            "no pins": [f"pin_motion={carried['motion']}"]}[case]
    base = {"cloth": carried["sheet"], "keyframes": f"{FRAMES}:{carried['wave']}",
            "pins": TOP}
    for item in sets:
        base[item.split("=")[0]] = item.split("=", 1)[1]
    if case == "no pins":
        del base["pins"]
    args = ["solve", "mesh_keyframes", "--out", str(carried["folder"] / "bad"), "--quiet"]
    assert main(args + [a for k, v in base.items() for a in ("--set", f"{k}={v}")]) == 2
    err = capsys.readouterr().err
    error = [line for line in err.splitlines() if not line.startswith("note: ")]
    assert len(error) == 1 and error[0].startswith(f"error: mesh_keyframes: {option}: "), err
    assert words in err, err


def box_body(folder, dt, frames, turn=0.3, shift=(0.3, 0.0, 0.05)):
    """A closed box behind the sheet's top row (its front face 1 mm behind the row, inside
    the contact layer), moving by ``shift`` and turning ``turn`` rad about z over ``frames``
    frames, as a PC2 cache beside its rest OBJ; returns the path and the rigid motion."""
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("igl")
    box = trimesh.creation.box(extents=(1.4, 0.2, 0.2))
    V = np.asarray(box.vertices) + [0.5, 0.101, -0.05]
    F = np.asarray(box.faces)

    def motion(t):
        s = t / (frames * dt)
        a = turn * s
        R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        return R, s * np.asarray(shift)

    centre = np.array([0.5, 0.0, 0.0])
    placed = [(V - centre) @ motion(n * dt)[0].T + centre + motion(n * dt)[1]
              for n in range(frames + 1)]
    write_obj(folder / "box_rest.obj", V, F)
    write_pc2(folder / "box.pc2", np.array(placed))
    return folder / "box.pc2", motion, centre


def test_pins_ride_on_a_moving_turning_body_and_its_contact_does_not_fight_them(carried):
    """The top row rides on a box that moves and turns, 1 mm off its face (inside the
    contact layer): the pins follow the box's rigid motion at every frame (to the PC2's
    float32), the free vertices still collide with the box."""
    dt = 1 / 60
    path, motion, centre = box_body(carried["folder"], dt, FRAMES)
    prob = problem(carried, pin_motion=None, bodies=str(path), pin_body="box")
    assert problem(carried, pin_motion=None, bodies=str(path), pin_body="0").size == prob.size
    traj = prob.simulate()
    pins = [int(i) for i in TOP.split(",")]
    start = prob.x0[pins]
    for n in range(FRAMES + 1):
        R, p = motion(n * dt)
        np.testing.assert_allclose(traj.x[n, pins], (start - centre) @ R.T + centre + p,
                                   atol=1e-6)
    assert prob.model.penetration(traj.x[-1][4:], FRAMES * dt) <= 5e-3


@pytest.mark.parametrize("source", ["motion", "body"])
def test_the_gradient_through_moving_pins_is_the_forward_pass_s_derivative(carried, source):
    """Along moving pins (a file's, a body's) the hand adjoint meets CasADi's exact reverse
    mode (the algebra) and central differences of simulate (the model)."""
    if source == "motion":
        prob = problem(carried, steps=6, keyframes=f"6:{carried['wave']}")
    else:
        path, _, _ = box_body(carried["folder"], 1 / 60, FRAMES)
        prob = problem(carried, steps=6, keyframes=f"6:{carried['wave']}", pin_motion=None,
                       bodies=str(path), pin_body="0")
    u = np.random.default_rng(2).normal(scale=0.02, size=prob.size)
    d = np.random.default_rng(3).standard_normal(prob.size)
    d /= np.linalg.norm(d)
    _, g = prob.objective_and_gradient(u, "adjoint")
    _, g_ref = prob.objective_and_gradient(u, "casadi")
    assert np.linalg.norm(g - g_ref) <= 1e-8 * np.linalg.norm(g_ref)
    assert_forward_derivative(prob, u, g @ d, d)
