"""A problem file that fails (on import or in build()) is reported as the user needs it: the
file, the line in that file, the exception; exit code 2; the library's own frames only with
--debug.  And `list` goes on past a broken file."""
import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.loading import ProblemFileError, list_problems, load_problem

RAISES = '''"""Raises in build()."""


def scale(k):
    return 1 / k


def build(k: int = 0):
    return scale(k)
'''
IMPORTS = '''"""Cannot import."""
import numpy as np
import casadi_keyframe_no_such_module
'''
NAME = '''"""A name error at import."""
SIZE = undefined_name + 1
'''
BAD_SHAPE = '''"""The library refuses what build() gives it."""
import numpy as np
from casadi_keyframe.objectives import CenterOfMassKeyframe
from casadi_keyframe.scenes.flocks import blob, flock_problem


def build(agents: int = 4):
    x0 = blob(agents + 1, (0, 0), 1.0, 2, np.random.default_rng(0))
    return flock_problem(agents=agents, steps=10, dt=0.05, seed=0, dim=2, x0=x0,
                         v0=np.zeros((agents, 2)), objective=CenterOfMassKeyframe(10, x=[1, 0]),
                         name="bad")
'''
CASES = {  # file text, the line reported, the exception
    "raises": (RAISES, "at line 5 (return 1 / k): ZeroDivisionError: division by zero"),
    "imports": (IMPORTS, "to import at line 3 (import casadi_keyframe_no_such_module): "
                         "ModuleNotFoundError: No module named 'casadi_keyframe_no_such_module'"),
    "name": (NAME, "to import at line 2 (SIZE = undefined_name + 1): NameError: name "
                   "'undefined_name' is not defined"),
    "shape": (BAD_SHAPE, "in build() at line 9 (return flock_problem(agents=agents, steps=10, "
                         "dt=0.05, seed=0, dim=2, x0=x0,): ValueError: initial positions x0 "
                         "must have shape (4, 2) (particles, dim), got (5, 2)"),
}


COMMANDS = {"solve": ["solve", "{path}", "--out", "{tmp}/out"], "show": ["show", "{path}"],
            "gradcheck": ["gradcheck", "{path}"],
            "sweep": ["sweep", "{path}", "--grid", "k=1,2", "--out", "{tmp}/sweep"]}
# an import fails in every command; build() runs in solve and gradcheck (show never builds,
# a sweep builds on its workers: there a failing build is a failed point with its reason)
RUNS = [(case, command) for case in ("imports", "name") for command in COMMANDS] + [
    (case, command) for case in ("raises", "shape") for command in ("solve", "gradcheck")]


@pytest.mark.parametrize("case, command", RUNS)
def test_a_failing_problem_file_is_one_short_report(case, command, tmp_path, capsys):
    text, expected = CASES[case]
    path = tmp_path / f"{case}.py"
    path.write_text(text)
    assert main([a.format(path=path, tmp=tmp_path) for a in COMMANDS[command]]) == 2
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert lines[0].startswith(f"error: problem file {path} failed ") and expected in lines[0]
    assert lines[1:] == ["  (--debug shows the whole traceback)"]
    assert "Traceback" not in err and "casadi_keyframe/" not in err


def test_debug_shows_the_library_frames_too(tmp_path, capsys):
    path = tmp_path / "raises.py"
    path.write_text(RAISES)
    assert main(["solve", str(path), "--debug"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "loading.py" in err and f'"{path}", line 5' in err
    assert err.splitlines()[-1].startswith("error: problem file")
    assert main(["--debug", "show", str(tmp_path / "missing.py")]) == 2  # before the command
    assert "Traceback" in capsys.readouterr().err


def test_the_python_api_raises_the_same_report_with_the_cause_kept(tmp_path):
    path = tmp_path / "raises.py"
    path.write_text(RAISES)
    with pytest.raises(ProblemFileError, match="at line 5") as err:
        load_problem(str(path))
    assert isinstance(err.value, ValueError)
    assert isinstance(err.value.__cause__, ZeroDivisionError)


def test_list_goes_on_past_a_broken_file(tmp_path, monkeypatch, capsys):
    (tmp_path / "good.py").write_text('"""A good problem."""\n')
    (tmp_path / "broken.py").write_text(IMPORTS)
    monkeypatch.setenv("CASADI_KEYFRAME_PROBLEMS", str(tmp_path))
    listed = dict(list_problems())
    assert listed["good"] == "A good problem."
    assert listed["broken"].startswith("(cannot be loaded: problem file")
    assert main(["list"]) == 0
    assert "broken" in capsys.readouterr().out
