"""The solve command's outcome: exit codes, signals, atomic files, --resume, render."""
import json
import signal
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest

from casadi_keyframe import adjoints
from casadi_keyframe.cli import main
from casadi_keyframe.saved import atomic_path, read_run
from casadi_keyframe.runs import exit_code

SMALL = ["flock_path", "--set", "agents=6", "--set", "steps=20", "--set", "tolerance=2"]


def temporaries(folder):
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name)


def start_solve(out, *extra):
    cmd = [sys.executable, "-m", "casadi_keyframe.cli", "solve", *SMALL, "--out", str(out),
           "--quiet", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def wait_for(path, proc, timeout=60.0, after_iteration=False):
    """Until ``path`` exists (with ``after_iteration``, a checkpoint of iteration 1 or later)."""
    end = time.monotonic() + timeout
    while not path.exists() or (after_iteration and _iterations(path) < 1):
        if proc.poll() is not None or time.monotonic() > end:
            proc.kill()
            pytest.fail(f"{path.name} never appeared:\n{proc.communicate()[0]}")
        time.sleep(0.02)


def _iterations(path) -> int:
    try:
        return int(np.load(path)["nit"])
    except (OSError, ValueError, KeyError, EOFError):  # being replaced right now
        return -1


def test_exit_codes_follow_the_status():
    assert [exit_code(s) for s in (0, 1, 2)] == [0, 3, 1]
    assert exit_code(3, signal.SIGINT) == exit_code(3) == 130
    assert exit_code(3, signal.SIGTERM) == 143


@pytest.mark.parametrize("method, sig, code", [("lbfgsb", signal.SIGINT, 130),
                                               ("lbfgsb", signal.SIGTERM, 143),
                                               ("ipopt", signal.SIGINT, 130)])
def test_a_signal_writes_the_best_result_and_render_and_resume_use_it(method, sig, code,
                                                                      tmp_path, capsys):
    out = tmp_path / "run"
    # finite differences: about 0.7 s per evaluation, so the search is still running
    proc = start_solve(out, "--gradient", "fd", "--maxiter", "500", "--method", method)
    wait_for(out / "checkpoint.npz", proc)
    proc.send_signal(sig)
    text = proc.communicate(timeout=60)[0]
    assert proc.returncode == code, text
    assert "pictures skipped" in text and f"render {out}" in text
    assert sorted(p.name for p in out.iterdir()) == ["checkpoint.npz", "result.npz",
                                                     "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == 3 and "interrupted" in summary["message"]
    saved = read_run(out / "result.npz")
    assert saved["meta"]["overrides"] == {"agents": 6, "steps": 20, "tolerance": 2}
    assert saved["u"].size == 240 and np.isfinite(saved["arrays"]["x"]).all()

    assert main(["render", str(out), "--no-animation"]) == 0
    assert (out / "keyframes.png").stat().st_size > 0 and (out / "convergence.png").is_file()
    again = tmp_path / "again"
    assert main(["solve", *SMALL, "--out", str(again), "--resume", str(out), "--maxiter", "2",
                 "--quiet", "--no-animation"]) == 3
    assert "start (resumed)" in capsys.readouterr().out
    resumed = json.loads((again / "summary.json").read_text())
    assert resumed["resumed_from"]["path"].endswith(".npz")
    assert resumed["fun"] <= summary["fun"]
    assert temporaries(out) == temporaries(again) == []


def test_a_second_ctrl_c_stops_at_once_and_leaves_whole_files(tmp_path):
    out = tmp_path / "run"
    proc = start_solve(out, "--gradient", "fd", "--maxiter", "500")
    wait_for(out / "checkpoint.npz", proc)  # the start's, written before the first iteration
    wait_for(out / "checkpoint.npz", proc, after_iteration=True)  # inside the search now
    proc.send_signal(signal.SIGINT)
    time.sleep(0.15)  # the first waits for the evaluation under way (about 0.5 s)
    proc.send_signal(signal.SIGINT)
    text = proc.communicate(timeout=60)[0]
    assert proc.returncode == 130, text
    assert temporaries(out) == [] and read_run(out / "checkpoint.npz")["u"].size == 240
    if (out / "result.npz").exists():  # the first signal's result, if written before
        assert read_run(out / "result.npz")["meta"]["status"] == 3
    else:
        assert "before the result was written" in text and f"--resume {out}" in text


def test_an_interrupt_while_drawing_leaves_no_truncated_gif(tmp_path):
    out = tmp_path / "run"
    proc = start_solve(out, "--set", "steps=200", "--maxiter", "3")  # a 151-frame GIF
    wait_for(out / "keyframes.png", proc)
    time.sleep(0.3)  # well into the animation (several seconds)
    proc.send_signal(signal.SIGINT)
    text = proc.communicate(timeout=60)[0]
    assert proc.returncode == 130, text
    assert "while drawing" in text
    assert not (out / "animation.gif").exists() and temporaries(out) == []
    assert read_run(out / "result.npz")["meta"]["status"] == 1  # written before drawing


def test_a_failed_search_exits_1_with_its_cause_and_keeps_the_best(tmp_path, capsys,
                                                                    monkeypatch):
    class WrongSign(adjoints.Adjoint):
        def evaluate(self, problem, u):
            found = super().evaluate(problem, u)
            return replace(found, gradient=-found.gradient)

    monkeypatch.setitem(adjoints.GRADIENTS, "adjoint", WrongSign)
    assert main(["solve", *SMALL, "--out", str(tmp_path), "--quiet", "--no-animation"]) == 1
    text = capsys.readouterr().out
    assert "line search failed" in text and "gradient may be inaccurate" in text
    assert "gradcheck flock_path --set agents=6 --set steps=20 --set tolerance=2" in text
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == 2 and not summary["success"]
    assert (tmp_path / "result.npz").is_file() and (tmp_path / "keyframes.png").is_file()


def test_the_iteration_limit_exits_3_and_resume_goes_on(tmp_path, capsys):
    assert main(["solve", *SMALL, "--out", str(tmp_path), "--maxiter", "3", "--quiet",
                 "--no-animation"]) == 3
    text = capsys.readouterr().out
    assert "iteration limit reached (3 iterations in this stage)" in text and f"--resume {tmp_path}" in text
    assert "--method lbfgsb --gradient adjoint --out" in text  # resumed the same way
    first = json.loads((tmp_path / "summary.json").read_text())
    assert main(["solve", *SMALL, "--out", str(tmp_path), "--resume",
                 str(tmp_path / "checkpoint.npz"), "--quiet", "--no-animation"]) == 0
    second = json.loads((tmp_path / "summary.json").read_text())
    assert second["resumed_from"]["nit"] == 3 and second["fun"] < first["fun"]


def test_the_time_limit_exits_3(tmp_path, capsys):
    """One finite-difference gradient takes longer than the limit, so the search stops at
    its first iteration (counted, not timed: a loaded machine is slower, not wrong)."""
    assert main(["solve", *SMALL, "--out", str(tmp_path), "--gradient", "fd", "--time-limit",
                 "0.5", "--quiet", "--no-animation"]) == 3
    assert "time limit reached (0.5 s)" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == 1 and summary["nit"] == 1


@pytest.mark.parametrize("change, message", [
    (["--set", "agents=7"], "overrides"),
    (["--set", "seed=1"], "overrides"),
])
def test_resume_refuses_another_run(change, message, tmp_path, capsys):
    assert main(["solve", *SMALL, "--out", str(tmp_path), "--maxiter", "2", "--quiet",
                 "--no-animation"]) == 3
    capsys.readouterr()
    assert main(["solve", *SMALL, *change, "--out", str(tmp_path / "b"), "--resume",
                 str(tmp_path), "--quiet", "--no-animation"]) == 2
    assert message in capsys.readouterr().err
    assert main(["solve", "flock_race", "--set", "agents=6", "--set", "steps=20", "--out",
                 str(tmp_path / "c"), "--resume", str(tmp_path), "--quiet"]) == 2
    assert "holds a run of problem 'flock_path'" in capsys.readouterr().err


def test_render_from_a_checkpoint_alone(tmp_path, capsys):
    assert main(["solve", *SMALL, "--out", str(tmp_path), "--maxiter", "2", "--quiet",
                 "--no-animation"]) == 3
    for name in ("result.npz", "summary.json", "keyframes.png", "convergence.png"):
        (tmp_path / name).unlink()
    assert main(["render", str(tmp_path), "--no-animation"]) == 0
    assert "simulating them" in capsys.readouterr().out
    assert (tmp_path / "keyframes.png").stat().st_size > 0
    assert main(["render", str(tmp_path / "nothing")]) == 2


def test_a_simulation_failing_at_the_start_is_reported_not_solved(tmp_path, capsys):
    assert main(["solve", *SMALL, "--set", "dt=1000", "--out", str(tmp_path), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "fails at the starting controls (passive)" in err and "blew up" in err
    assert not (tmp_path / "result.npz").exists()


def test_atomic_files_are_whole_or_absent(tmp_path):
    from casadi_keyframe import render

    path = tmp_path / "a.txt"
    path.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(path) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert path.read_text() == "old" and temporaries(tmp_path) == []

    import matplotlib.pyplot as plt

    fig = plt.figure()

    def draw(n):
        if n == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render.write_gif(fig, draw, range(10), tmp_path / "a.gif", fps=10)
    plt.close(fig)
    assert not (tmp_path / "a.gif").exists() and temporaries(tmp_path) == []


def test_misses_say_what_their_rms_is_over():
    from casadi_keyframe.optimize.report import format_misses

    line = format_misses([{"term": "StateKeyframe@60", "particles": 416,
                           "rms_position_error": 0.01}, {"term": "RegionTarget@50",
                                                         "fraction_inside": 1.0}])
    assert line == ("StateKeyframe@60 over 416 particles: rms_position_error 0.01; "
                    "RegionTarget@50 fraction_inside 1")
