"""problems/mesh_keyframes.py from the command line: bad input refused with the option's
name (exit code 2), show documents every override, and a reduced sheet read from OBJ files
solved onto its wave and fold (the 30 x 30 run is in test_slow_figures)."""
import json

import numpy as np
import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.loading import load_module, overrides_of
from casadi_keyframe.scenes.mesh_targets import write_sheet_and_targets


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshes")
    paths = write_sheet_and_targets(folder, 6, 6)
    small = write_sheet_and_targets(folder / "small", 5, 6)
    (folder / "junk.obj").write_text("v 0 0\nthis is not a mesh\nf 1\n")
    return {**{k: str(v) for k, v in paths.items()}, "small": str(small["wave"]),
            "junk": str(folder / "junk.obj"), "folder": folder}


def bad(files, *sets):
    args = ["solve", "mesh_keyframes", "--out", str(files["folder"] / "out"), "--quiet"]
    return args + [a for s in sets for a in ("--set", s)]


@pytest.mark.parametrize("case, option, words", [
    ("missing", "cloth", "no such file"),
    ("junk", "cloth", "needs at least 3 vertices"),
    ("vertices", "keyframes", "has 30 vertices, the cloth 36"),
    ("pins", "pins", "pinned vertex 36 is out of range"),
    ("horizon", "keyframes", "frame 40 (FOLD) is beyond the horizon of steps=30"),
    ("target missing", "keyframes", "no such file"),
    ("form", "keyframes", "expected FRAME:FILE pairs"),
    ("group", "pin_group", "no vertex set named 'top'"),
])
def test_bad_input_exits_2_naming_the_option(files, capsys, case, option, words):
    cloth, wave = f"cloth={files['sheet']}", f"keyframes=40:{files['wave']}"
    sets = {"missing": [f"cloth={files['folder']}/none.obj", wave],
            "junk": [f"cloth={files['junk']}", wave],
            "vertices": [cloth, f"keyframes=20:{files['small']}"],
            "pins": [cloth, wave, "pins=0,36"],
            "horizon": [cloth, f"keyframes=20:{files['wave']},40:{files['fold']}", "steps=30"],
            "target missing": [cloth, "keyframes=20:nowhere.obj"],
            "form": [cloth, "keyframes=wave.obj"],
            "group": [cloth, wave, "pin_group=top"]}[case]
    assert main(bad(files, *sets)) == 2
    err = capsys.readouterr().err
    error = [line for line in err.splitlines() if not line.startswith("note: ")]
    assert len(error) == 1 and error[0].startswith(f"error: mesh_keyframes: {option}: "), err
    assert words.replace("FOLD", files["fold"]) in err, err
    assert "problem file" not in err and "show mesh_keyframes" not in err, err


def test_the_cloth_file_given_as_a_target_is_refused(files, capsys):
    assert main(bad(files, f"cloth={files['sheet']}", f"keyframes=10:{files['sheet']}")) == 2
    assert "keyframes: frame 10's target" in capsys.readouterr().err


def test_a_run_stands_alone_and_refuses_changed_inputs(files, tmp_path, capsys, monkeypatch):
    """Solved from relative paths, a run renders and exports from another folder; once a
    target file is edited, render, export and --resume refuse it by the file's name."""
    import shutil

    work = tmp_path / "work"
    (work / "meshes").mkdir(parents=True)
    for name in ("sheet", "wave"):
        shutil.copy(files[name], work / "meshes" / f"{name}.obj")
    monkeypatch.chdir(work)
    sets = ["--set", "cloth=meshes/sheet.obj", "--set", "keyframes=8:meshes/wave.obj",
            "--set", "steps=8"]
    assert main(["solve", "mesh_keyframes", *sets, "--maxiter", "1", "--out", "run", "--quiet",
                 "--no-animation", "--no-viewer"]) in (0, 1, 3)
    summary = json.loads((work / "run" / "summary.json").read_text())
    assert set(summary["inputs"]) == {str(work / "meshes" / f"{n}.obj") for n in ("sheet", "wave")}
    monkeypatch.chdir(tmp_path)
    assert main(["render", str(work / "run"), "--no-animation"]) == 0
    assert main(["export", str(work / "run"), "--format", "pc2"]) == 0
    with open(work / "meshes" / "wave.obj", "a") as f:
        f.write("# edited\n")
    capsys.readouterr()
    assert main(["render", str(work / "run"), "--no-animation"]) == 2
    assert f"{work / 'meshes' / 'wave.obj'}, which has changed since" in capsys.readouterr().err
    monkeypatch.chdir(work)
    assert main(["solve", "mesh_keyframes", *sets, "--maxiter", "1", "--out", "again",
                 "--resume", "run", "--quiet", "--no-animation", "--no-viewer"]) == 2
    assert "which has changed since" in capsys.readouterr().err


def test_show_documents_every_override(capsys):
    assert main(["show", "mesh_keyframes"]) == 0
    out = capsys.readouterr().out
    doc = out.split("overrides (--set NAME=VALUE):")[0]
    for o in overrides_of(load_module("mesh_keyframes")):
        assert f"``{o.name}``" in doc, f"{o.name} is not described"
    assert "keyframes=40:wave.obj,80:fold.obj" in doc and "exit code 2" in doc


def test_a_small_sheet_from_obj_files_reaches_its_wave_and_fold(files, tmp_path, capsys):
    """6 x 6 sheet, 30 frames: the two targets within 1 cm rms, no spring past 1.3."""
    out = tmp_path / "run"
    code = main(["solve", "mesh_keyframes", "--set", f"cloth={files['sheet']}", "--set",
                 f"keyframes=15:{files['wave']},30:{files['fold']}", "--set", "pins=0,5",
                 "--maxiter", "60", "--out", str(out), "--quiet", "--no-animation",
                 "--no-viewer"])
    assert code in (0, 1, 3)
    breakdown = json.loads((out / "summary.json").read_text())["breakdown"]
    misses = {m["term"]: m["rms_position_error"] for m in breakdown["misses"]}
    assert set(misses) == {"MeshKeyframe@15", "MeshKeyframe@30"}
    assert max(misses.values()) < 0.01, misses
    assert breakdown["physical"]["max_stretch"] <= 1.3
    x = np.load(out / "result.npz")["x"]
    assert x.shape == (31, 36, 3)


def test_colliders_control_kind_and_pin_box_overrides(files):
    from casadi_keyframe.controls import InitialVelocity
    from casadi_keyframe.loading import load_problem
    from casadi_keyframe.models.contact.colliders import Plane, Sphere

    prob = load_problem("mesh_keyframes", cloth=files["sheet"], keyframes=f"10:{files['wave']}",
                        pin_box=(-1, -1, -0.01, 2, 1, 1), ground=-1.5,
                        spheres=(0.5, 0.3, -0.5, 0.1, 0.2, 0.3, -0.8, 0.05),
                        control="velocity", steps=12, dt=1 / 30)
    assert [type(b) for b in prob.model.colliders] == [Plane, Sphere, Sphere]
    np.testing.assert_array_equal(prob.model.pinned, np.arange(6))  # the top row
    assert isinstance(prob.controls, InitialVelocity) and not prob.has_guess
    assert (prob.steps, prob.dt) == (12, 1 / 30)


def test_bad_spheres_and_box_are_refused_by_name(files, capsys):
    cloth, wave = f"cloth={files['sheet']}", f"keyframes=10:{files['wave']}"
    assert main(bad(files, cloth, wave, "spheres=0,0,0")) == 2
    assert "mesh_keyframes: spheres: give x,y,z,radius for each sphere" in capsys.readouterr().err
    assert main(bad(files, cloth, wave, "pin_box=5,5,5,6,6,6")) == 2
    assert "mesh_keyframes: pin_box: " in capsys.readouterr().err


def test_guesses_aim_land_track_or_start_from_zero(files):
    """"land" starts on both keyframes (inverse steps at each, not only the last), "track"
    near them with far gentler forces, "aim" (the default) nearer than "track" and still
    far gentler than "land", "none" from zero forces."""
    from casadi_keyframe.loading import load_problem

    def start(guess):
        extra = {} if guess is None else {"guess": guess}
        prob = load_problem("mesh_keyframes", cloth=files["sheet"], pins=(0, 5),
                            keyframes=f"15:{files['wave']},30:{files['fold']}", **extra)
        u = prob.initial_controls()
        misses = [m["rms_position_error"] for m in prob.breakdown(u)["misses"]]
        return prob, u, misses

    landed, u_land, on = start("land")
    tracked, u_track, near = start("track")
    aimed, u_aim, nearer = start(None)
    passive, u_zero, off = start("none")
    assert max(on) < 1e-9 and not np.any(u_zero)
    assert max(near) < 0.5 * min(off) and min(near) > 1e-6
    assert max(nearer) < max(near)
    np.testing.assert_array_equal(u_aim, start("aim")[1])
    assert tracked.control_cost(u_track)[0] < 0.1 * landed.control_cost(u_land)[0]
    assert aimed.control_cost(u_aim)[0] < 0.1 * landed.control_cost(u_land)[0]
