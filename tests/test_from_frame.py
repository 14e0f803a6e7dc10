"""``solve --resume RUN --from-frame K``: RUN's frames 0..K kept bit for bit, frames K+1..
solved against the problem as it is now (a changed keyframe), the result a whole shot that
``simulate`` replays exactly; the tail problem steps as the whole run does after K (moving
pins and a moving body see the right time), and its gradient is the forward pass's
derivative; every bad input exits 2 naming ``--from-frame``."""
import json

import numpy as np
import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.export.obj import write_obj
from casadi_keyframe.loading import load_problem
from casadi_keyframe.runs.from_frame import tail_problem
from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, write_sheet_and_targets

from helpers import assert_forward_derivative

KEYS = "20:{wave},40:{fold}"


@pytest.fixture(scope="module")
def first(tmp_path_factory):
    """A 6 x 6 sheet solved onto a wave at frame 20 and a fold at frame 40 (RUN), and a
    60 degree fold to change the last keyframe to."""
    folder = tmp_path_factory.mktemp("from_frame")
    paths = {k: str(v) for k, v in write_sheet_and_targets(folder, 6, 6).items()}
    vertices, quads = hanging_sheet(6, 6)
    paths["fold60"] = str(write_obj(folder / "fold60.obj", fold(vertices, angle=60.0), quads))
    paths["folder"], paths["run"] = folder, str(folder / "run")
    assert main(solve_args(paths, "fold", paths["run"])) == 0
    return paths


def solve_args(files, fold_name, out, *more, sets=()):
    keys = KEYS.format(wave=files["wave"], fold=files[fold_name])
    given = {"cloth": files["sheet"], "keyframes": keys, "pins": "0,5", **dict(sets)}
    return (["solve", "mesh_keyframes", "--out", str(out), "--quiet", "--no-animation",
             "--no-viewer"] + [a for k, v in given.items() for a in ("--set", f"{k}={v}")]
            + list(more))


def test_the_kept_frames_are_bit_identical_and_the_new_keyframe_is_hit(first, tmp_path):
    out = tmp_path / "again"
    args = solve_args(first, "fold60", out, "--resume", first["run"], "--from-frame", "30")
    assert main(args) == 0  # converged: the new fold within its tolerance
    a, b = np.load(f"{first['run']}/result.npz"), np.load(out / "result.npz")
    assert np.array_equal(a["x"][:31], b["x"][:31]) and np.array_equal(a["v"][:31], b["v"][:31])
    assert np.array_equal(a["u"][:b["u"].size * 30 // 40], b["u"][:b["u"].size * 30 // 40])
    assert not np.array_equal(a["x"][31:], b["x"][31:])
    now = load_problem("mesh_keyframes", cloth=first["sheet"], pins=(0, 5),
                       keyframes=KEYS.format(wave=first["wave"], fold=first["fold60"]))
    assert np.array_equal(now.simulate(b["u"], records=False).x, b["x"])  # a whole shot
    summary = json.loads((out / "summary.json").read_text())
    assert summary["resumed_from"]["from_frame"] == 30
    assert summary["breakdown"]["misses"][1]["term"] == "MeshKeyframe@40"
    assert np.load(out / "checkpoint.npz")["u"].size == now.size  # whole-shot controls too


@pytest.mark.parametrize("case, words", [
    ("beyond", "--from-frame 45 is beyond"),
    ("before", "--from-frame 10 is before the first keyframe (frame 20): nothing before a first "
               "keyframe is worth keeping; solve the whole shot instead, without --from-frame"),
    ("last", "--from-frame 40 leaves no keyframe after it"),
    ("no run", "--from-frame 30 keeps a run's motion up to that frame: give the run with "
               "--resume RUN"),
    ("dt", "--from-frame: "),
    ("pins", "does not move the pinned vertices as mesh_keyframes does now"),
    ("cloth", "the cloth cannot change"),
    ("checkpoint", "holds no motion (a checkpoint)"),
    ("coarse", "does not combine with --continuation"),
])
def test_bad_input_exits_2_naming_the_option(first, tmp_path, capsys, case, words):
    frame = {"beyond": "45", "before": "10", "last": "40"}.get(case, "30")
    run = f"{first['run']}/checkpoint.npz" if case == "checkpoint" else first["run"]
    more = ([] if case == "no run" else ["--resume", run]) + ["--from-frame", frame]
    more += ["--continuation", "1/30"] if case == "coarse" else []
    files, sets = first, {"dt": {"dt": "0.02"}, "pins": {"pins": "0,4"}}.get(case, {})
    if case == "cloth":  # a 5 x 5 sheet with its own targets
        files = {k: str(v) for k, v in write_sheet_and_targets(tmp_path / "five", 5, 5).items()}
        files["fold60"], sets = files["fold"], {"pins": "0,4"}
    assert main(solve_args(files, "fold60", tmp_path / "bad", *more, sets=sets.items())) == 2
    err = capsys.readouterr().err
    assert "--from-frame" in err and words in err, err


@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    """A 4 x 4 sheet whose top row follows a file and that falls past a moving box."""
    from casadi_keyframe.scenes.mesh_targets import write_carried_sheet
    from test_pin_motion import box_body
    folder = tmp_path_factory.mktemp("moving")
    files = write_carried_sheet(folder, 4, 4, 12, shift=(0.2, 0.0, 0.0))
    box, _, _ = box_body(folder, 1 / 60, 12, shift=(0.0, -0.3, 0.0))
    return load_problem("mesh_keyframes", cloth=str(files["sheet"]), pins=(0, 1, 2, 3),
                        keyframes=f"6:{files['wave']},12:{files['wave']}", guess="none",
                        pin_motion=str(files["motion"]), bodies=str(box))


def test_the_tail_steps_as_the_whole_run_after_the_frame(moving):
    """Stepped from frame K with the step numbers moved on by K and what step K-1 carried,
    the tail is the whole run's frames K.. bit for bit (moving pins and a moving body)."""
    prob, k = moving, 6
    u = np.random.default_rng(4).normal(scale=0.05, size=prob.size)
    whole = prob.simulate(u)
    carried = prob.integrator.carry(prob.model, whole.records[k - 1])
    tail = tail_problem(prob, k, whole.x[k], whole.v[k], carried)
    assert [t.frame for t in tail.objective_terms.state_terms] == [6]
    run = tail.simulate(u[u.size * k // prob.steps:])
    assert np.array_equal(run.x, whole.x[k:]) and np.array_equal(run.v, whole.v[k:])


def test_the_tail_s_gradient_is_the_forward_pass_s_derivative(moving):
    prob, k = moving, 6
    whole = prob.simulate()
    tail = tail_problem(prob, k, whole.x[k], whole.v[k],
                        prob.integrator.carry(prob.model, whole.records[k - 1]))
    u = np.random.default_rng(5).normal(scale=0.02, size=tail.size)
    d = np.random.default_rng(6).standard_normal(tail.size)
    d /= np.linalg.norm(d)
    _, g = tail.objective_and_gradient(u, "adjoint")
    _, g_ref = tail.objective_and_gradient(u, "casadi")  # its parameters at t + K dt
    assert np.linalg.norm(g - g_ref) <= 1e-8 * np.linalg.norm(g_ref)
    assert_forward_derivative(tail, u, g @ d, d)


def test_a_keyframe_the_kept_frames_miss_fails_the_whole_shot(first, tmp_path, capsys):
    """The frames after K meet their goal, but RUN (zero forces) misses the wave at frame
    20, which lies in the kept frames: exit 1, and the message says why."""
    passive = solve_args(first, "fold", tmp_path / "passive", "--maxiter", "1", "--method",
                         "lbfgsb", sets={"guess": "none", "rest_band": "0"}.items())
    assert main(passive) in (1, 3)
    again = solve_args(first, "fold60", tmp_path / "again", "--resume",
                       str(tmp_path / "passive"), "--from-frame", "30",
                       sets={"rest_band": "0"}.items())
    assert main(again) == 1
    summary = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert "meet their goal, the whole shot does not" in summary["message"]
    assert "MeshKeyframe@20" in summary["message"], summary["message"]


@pytest.mark.parametrize("route", ["adjoint", "swapped"])
def test_the_tail_s_gradient_is_the_whole_shot_s_for_the_frames_after(moving, route):
    """The tail's gradient (the exact adjoint, the paper's swapped one) is the whole shot's
    for the controls after K: the shifted backward steps see the right time."""
    import warnings
    prob, k = moving, 6
    u = np.random.default_rng(7).normal(scale=0.05, size=prob.size)
    whole = prob.simulate(u)
    tail = tail_problem(prob, k, whole.x[k], whole.v[k],
                        prob.integrator.carry(prob.model, whole.records[k - 1]))
    cut = u.size * k // prob.steps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = prob.objective_and_gradient(u, route)[1][cut:]
        g_tail = tail.objective_and_gradient(u[cut:], route)[1]
    assert np.linalg.norm(g_tail - g) <= 1e-10 * np.linalg.norm(g)
