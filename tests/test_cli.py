"""The command line: list, solve (files written) and gradcheck."""
import json

import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.cli.values import parse_overrides


def test_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("flock_path", "flock_race", "flock_shapes"):
        assert name in out


def test_overrides_parse_python_literals():
    assert parse_overrides(["agents=5", "cutoff=hard", "dt=0.1"]) == {
        "agents": 5, "cutoff": "hard", "dt": 0.1}


def test_solve_writes_results_and_pictures(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["solve", "flock_path", "--set", "agents=10", "--set", "steps=40",
                 "--maxiter", "15", "--out", str(out), "--quiet"])
    assert code == 3  # stopped at --maxiter before converging: written, with a hint
    assert "iteration limit reached (15 iterations in this stage)" in capsys.readouterr().out
    for name in ("result.npz", "summary.json", "animation.gif", "convergence.png",
                 "keyframes.png", "checkpoint.npz"):
        assert (out / name).stat().st_size > 0, name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["overrides"] == {"agents": 10, "steps": 40}
    assert summary["nit"] >= 1 and summary["breakdown"]["misses"]


def test_solve_reports_bad_overrides(capsys):
    assert main(["solve", "flock_path", "--set", "agentz=3"]) == 2
    assert "unknown override" in capsys.readouterr().err


def test_gradcheck_prints_agreement(capsys):
    assert main(["gradcheck", "flock_race", "--set", "agents=6", "--set", "steps=15",
                 "--directions", "1", "--routes", "adjoint,casadi"]) == 0
    out = capsys.readouterr().out
    line = next(l for l in out.splitlines() if l.strip().startswith("adjoint"))
    assert float(line.split("relative error")[1].split()[0]) < 1e-8


def test_solve_in_augmented_lagrangian_rounds(tmp_path, capsys):
    out = tmp_path / "rounds"
    code = main(["solve", "cloth_shapes", "--set", "rows=4", "--set", "steps=12",
                 "--maxiter", "5", "--rounds", "2", "--weight-growth", "10", "--out", str(out),
                 "--quiet", "--no-animation"])
    assert code == 3  # the last round stopped at --maxiter
    text = capsys.readouterr().out
    assert "start (passive): objective" in text and "rms_position_error" in text
    assert "round 0: weight x1," in text and "round 1: weight x10," in text
    assert text.count("iteration limit reached (5 iterations in this stage)") >= 3  # each round's message, the result's
    assert text.count("physical: largest stretch") == 2  # the start's and the result's
    summary = json.loads((out / "summary.json").read_text())
    physical = summary["breakdown"]["physical"]
    assert physical["max_stretch"] >= 1 and "max_penetration" not in physical  # no colliders
    assert [s["weight_scale"] for s in summary["stages"]] == [1.0, 10.0]
    assert summary["message"].startswith("2 augmented-Lagrangian rounds")


@pytest.mark.parametrize("flag, value", [("--rounds", "0"), ("--weight-growth", "0.5")])
def test_bad_rounds_are_refused(flag, value, tmp_path, capsys):
    code = main(["solve", "cloth_shapes", "--set", "rows=3", "--set", "steps=6", flag, value,
                 "--out", str(tmp_path), "--quiet", "--no-animation"])
    assert code == 2
    assert flag.strip("-").replace("-", "_") in capsys.readouterr().err
