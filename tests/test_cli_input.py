"""Bad command-line and override input: a message naming the input and the fix, exit code 2
(1 for a simulation that fails), never a traceback."""
import errno
import subprocess
import sys
from pathlib import Path

import pytest

from casadi_keyframe import cli, load_problem
from casadi_keyframe.saved import files
from casadi_keyframe.cli import main
from casadi_keyframe.cli.values import parse_overrides
from casadi_keyframe.loading import (OverrideError, check_overrides, list_problems,
                                     load_module, overrides_of)



def run_cli(*args):
    """The installed command as a user runs it: (exit code, stdout, stderr)."""
    script = Path(sys.executable).parent / "casadi-keyframe"
    command = [str(script)] if script.exists() else [sys.executable, "-m", "casadi_keyframe.cli"]
    done = subprocess.run(command + list(args), capture_output=True, text=True, timeout=300)
    return done.returncode, done.stdout, done.stderr


def test_a_missing_problem_path_is_an_error_not_the_builtin_problem(tmp_path):
    missing = tmp_path / "nowhere" / "flock_path.py"
    code, out, err = run_cli("solve", str(missing), "--out", str(tmp_path / "out"))
    assert code == 2, out
    assert str(missing) in err and "does not exist" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "result.npz").exists()
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_problem("some/dir/flock_path")


def test_a_misspelt_problem_name_suggests_the_right_one(capsys):
    assert main(["show", "flock_pth"]) == 2
    assert "did you mean flock_path?" in capsys.readouterr().err


def test_fractions_parse_as_floats():
    assert parse_overrides(["dt=1/60", "ring_center=(1, 2.5, 0)", "agents=10.0"]) == {
        "dt": 1 / 60, "ring_center": (1, 2.5, 0), "agents": 10.0}


def test_a_fraction_time_step_solves(tmp_path, capsys):
    assert main(["gradcheck", "flock_path", "--set", "agents=4", "--set", "steps=6",
                 "--set", "dt=1/60", "--directions", "0"]) == 0


@pytest.mark.parametrize("problem, item, expected", [
    ("flock_path", "agents=ten", "agents must be an integer in [1, inf) (default 100), got 'ten'"),
    ("flock_path", "agents=1e", "agents must be an integer in [1, inf) (default 100), got '1e'"),
    ("flock_path", "agents=10.5", "agents must be an integer in [1, inf) (default 100), got 10.5"),
    ("flock_path", "agents=-5", "agents must be an integer in [1, inf) (default 100), got -5"),
    ("flock_path", "keyframes=0", "keyframes must be an integer in [1, inf) (default 8), got 0"),
    ("flock_path", "dt=0", "dt must be a number in (0, inf)"),
    ("flock_path", "dt=1/0", "dt must be a number in (0, inf)"),
    ("flock_path", "cutoff=soft", "cutoff must be one of 'smooth', 'hard'"),
    ("flock_shapes", "steps=1", "steps must be an integer in [2, inf)"),
    ("cloth_toss", "ring_center=(1,2)", "ring_center must be 3 numbers"),
    ("cape_blend", "guess=psychic", "guess must be one of 'tracking', 'passive'"),
    ("flock_path", "agentz=3", "unknown override agentz (did you mean agents?)"),
    ("flock_path", "agents", "--set expects KEY=VALUE"),
])
def test_bad_overrides_are_named_with_type_range_and_default(problem, item, expected, tmp_path,
                                                               capsys):
    assert main(["solve", problem, "--set", item, "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert expected in err, err
    assert list(tmp_path.iterdir()) == []  # refused before the solve wrote anything


def test_every_bad_override_is_reported_at_once():
    with pytest.raises(OverrideError, match=r"agents must .*; dim must .*; wander must"):
        load_problem("flock_path", agents=0, dim=4, wander=-1.0)


def test_an_integer_override_takes_a_whole_float():
    assert load_problem("flock_path", agents=10.0, steps=5).x0.shape == (10, 2)


@pytest.mark.parametrize("name", [n for n, _ in list_problems()])
def test_every_problem_declares_ranges_its_defaults_satisfy(name):
    module = load_module(name)
    overrides = overrides_of(module)
    numbers = [o.name for o in overrides if o.kind in ("int", "float")]
    assert set(numbers) <= set(module.RANGES), f"{name}: no range for {set(numbers) - set(module.RANGES)}"
    assert [o.name for o in overrides if o.kind == "any"] == []
    defaults = {o.name: o.default for o in overrides}
    assert check_overrides(module, defaults) == defaults


def test_maxiter_zero_is_refused_not_ignored(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["solve", "flock_path", "--maxiter", "0"])
    assert stop.value.code == 2
    assert "--maxiter: expects a whole number >= 1, got 0" in capsys.readouterr().err


def test_an_out_folder_under_a_file_is_refused_before_the_build(tmp_path, capsys, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setattr(cli.commands, "load_problem", lambda *a, **k: pytest.fail("built the problem"))
    assert main(["solve", "flock_path", "--out", str(blocker / "run")]) == 2
    err = capsys.readouterr().err
    assert f"cannot write the output folder {blocker / 'run'} (--out): {blocker} is a file" in err


def test_an_unwritable_out_folder_is_refused_before_the_build(tmp_path, capsys, monkeypatch):
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(files.tempfile, "TemporaryFile", read_only)
    monkeypatch.setattr(cli.commands, "load_problem", lambda *a, **k: pytest.fail("built the problem"))
    assert main(["solve", "flock_path", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert f"cannot write the output folder {tmp_path / 'run'} (--out): Read-only file system" in err


@pytest.mark.parametrize("command", ["solve", "gradcheck"])
def test_a_simulation_that_blows_up_at_the_start_is_a_one_line_failure(command, tmp_path,
                                                                         capsys):
    args = [command, "flock_path", "--set", "agents=20", "--set", "steps=20",
            "--set", "dt=1000"] + (["--out", str(tmp_path), "--quiet"] if command == "solve"
                                   else [])
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "blew up at step" in err and "reduce dt" in err


def test_list_prints_whole_first_sentences_and_points_to_show(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert max(len(line) for line in out.splitlines()) <= 100
    text = " ".join(out.split())
    assert "cloth_shapes Fig. 4: a piece of cloth hanging from its top corners swings into " \
           "shapes given as target positions: forward, into a wave, then back." in text
    assert "casadi-keyframe show PROBLEM" in text


def test_show_prints_description_overrides_and_solve_defaults(capsys):
    assert main(["show", "flock_path"]) == 0
    out = capsys.readouterr().out
    assert "Fig. 3: a flock of 100 agents follows a curved path" in out
    rows = {line.split()[0]: line.split() for line in out.splitlines() if line.startswith("  ")}
    assert rows["agents"] == ["agents", "int", "100", "[1,", "inf)"]
    assert rows["dt"][:3] == ["dt", "float", "0.05"]
    assert rows["cutoff"] == ["cutoff", "str", "smooth", "smooth,", "hard"]
    assert "solve defaults: method lbfgsb, maxiter 200" in out
    assert main(["show", "cloth_toss"]) == 0
    assert "ring_center    3 floats  (1.5, 0.0, 2.0)" in capsys.readouterr().out


def test_figure_claims_match_the_paper():
    """Fig. 1 is both the flock's square and cross and the cloth arch; every other figure is
    one problem (mesh_keyframes is no figure: the meshes-in problem of issue 27)."""
    claims = {name: summary.split(":")[0] for name, summary in list_problems()}
    assert claims == {"flock_shapes": "Fig. 1 (its flock half)",
                      "cloth_arch": "Fig. 1 (its cloth half)", "flock_race": "Fig. 2",
                      "flock_path": "Fig. 3", "cloth_shapes": "Fig. 4", "cloth_toss": "Fig. 5",
                      "cape_blend": "Fig. 6", "mesh_keyframes": "Meshes in"}


@pytest.mark.parametrize("args, expected", [
    (["gradcheck", "flock_path", "--directions", "-1"], "--directions: expects a whole number >= 0"),
    (["gradcheck", "flock_path", "--h", "0"], "--h: expects a number > 0, got 0"),
    (["gradcheck", "flock_path", "--scale", "nan"], "--scale: expects a number >= 0, got nan"),
])
def test_bad_numeric_options_are_refused(args, expected, capsys):
    with pytest.raises(SystemExit) as stop:
        main(args)
    assert stop.value.code == 2 and expected in capsys.readouterr().err


def test_a_bad_continuation_is_an_input_error(tmp_path, capsys):
    assert main(["solve", "flock_path", "--set", "agents=4", "--set", "steps=5",
                 "--continuation", "1/0", "--out", str(tmp_path), "--quiet"]) == 2
    assert "--continuation expects time steps" in capsys.readouterr().err


@pytest.mark.parametrize("text, expected", [
    ("x = 1\n", "has no build(**overrides) function"),
    ("def build(:\n", "is not valid Python: invalid syntax (line 1)"),
])
def test_a_broken_problem_file_is_named(text, expected, tmp_path, capsys):
    path = tmp_path / "mine.py"
    path.write_text(text)
    for command in ("solve", "show"):
        assert main([command, str(path)]) == 2
        err = capsys.readouterr().err
        assert str(path) in err and expected in err


def test_solve_records_the_overrides_as_build_got_them(tmp_path):
    """``agents=10.0`` builds 10 agents and is written as 10, and ``dt=1/30`` as a number."""
    import json

    code = main(["solve", "flock_path", "--set", "agents=6.0", "--set", "steps=10",
                 "--set", "dt=1/30", "--maxiter", "2", "--out", str(tmp_path), "--quiet",
                 "--no-animation"])
    assert code in (0, 3)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["overrides"] == {"agents": 6, "steps": 10, "dt": 1 / 30}
    assert isinstance(summary["overrides"]["agents"], int)


def test_a_hint_gives_the_overrides_as_set_reads_them_back():
    from casadi_keyframe.runs.report import set_value

    given = {"pins": "0,7", "agents": "8", "dt": "0.02", "collision": "guarded"}
    parsed = parse_overrides([f"{k}={v}" for k, v in given.items()])
    assert {k: set_value(v) for k, v in parsed.items()} == given
    assert parse_overrides([f"pins={set_value(parsed['pins'])}"]) == {"pins": parsed["pins"]}


@pytest.mark.parametrize("args, said", [
    (["--shooting", "garbage"], "--shooting expects KEY=VALUE such as init=blend,workers=2"),
    (["--shooting", "init=foo", "--segments", "2"], "--shooting: shooting init must be one of"),
    (["--homotopy", "garbage"], "--homotopy expects KEY=VALUE such as contact=3"),
    (["--homotopy", "agents=0"], "--homotopy: flock_path: agents must be"),
    (["--shooting", "workers=2"], "--shooting workers (or --scheduler) set multiple shooting's "
                                  "options, but this run has none: give --segments K"),
])
def test_each_option_names_itself_and_what_it_needs(args, said, capsys, tmp_path):
    code = main(["solve", "flock_path", "--set", "agents=4", "--set", "steps=10", "--quiet",
                 "--out", str(tmp_path), *args])
    assert code == 2 and said in capsys.readouterr().err


def test_a_method_option_reaches_the_method_checked_before_the_build(tmp_path, capsys,
                                                                     monkeypatch):
    """--option KEY=VALUE reaches any option the method documents (gauss-newton's radius),
    is checked against the method's own before the problem is built, and the run's resume
    line gives it back."""
    import casadi_keyframe.loading as loading

    common = ["solve", "flock_race", "--set", "agents=8", "--set", "steps=40", "--method",
              "gauss-newton", "--quiet", "--no-animation", "--no-viewer", "--out",
              str(tmp_path)]
    assert main([*common, "--maxiter", "1", "--option", "radius=0.5"]) == 3
    assert "--method gauss-newton --gradient adjoint --option radius=0.5" in (
        capsys.readouterr().out)
    built = []
    monkeypatch.setattr(loading, "build_problem", lambda *a, **k: built.append(a))
    assert main([*common, "--option", "radius=-1"]) == 2
    assert "Gauss-Newton option 'radius' must be a number > 0" in capsys.readouterr().err
    assert main([*common, "--option", "radiu=1"]) == 2
    assert "did you mean 'radius'?" in capsys.readouterr().err and built == []
