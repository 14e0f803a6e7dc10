"""Output paths are checked before any work, in the command line and in Python, with a
message that names the option: export --out, render's folder, solve(checkpoint=)."""
import errno

import numpy as np
import pytest

from casadi_keyframe import load_problem, solve
from casadi_keyframe.saved import files, folder
from casadi_keyframe.cli import main
from casadi_keyframe.export import export


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    assert main(["solve", "flock_path", "--set", "agents=4", "--set", "steps=10",
                 "--maxiter", "2", "--out", str(out), "--quiet", "--no-animation",
                 "--no-viewer"]) in (0, 3)
    return out


def _read_only(monkeypatch):
    def refuse(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")
    monkeypatch.setattr(files.tempfile, "TemporaryFile", refuse)


def _never_read(monkeypatch):
    monkeypatch.setattr(folder, "read_run", lambda *a: pytest.fail("read the result first"))


def test_export_out_under_a_file_is_refused_before_reading(run, tmp_path, capsys, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    _never_read(monkeypatch)
    assert main(["export", str(run), "--format", "pc2", "--out", str(blocker / "x")]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: cannot write the output folder {blocker / 'x'} (--out): {blocker} "
                   "is a file, not a folder; choose another --out\n")


def test_export_into_a_read_only_folder_names_the_option(run, tmp_path, capsys, monkeypatch):
    _never_read(monkeypatch)
    _read_only(monkeypatch)
    assert main(["export", str(run), "--format", "obj", "--out", str(tmp_path / "x")]) == 2
    assert "(--out): Read-only file system; choose another --out" in capsys.readouterr().err
    assert main(["export", str(run), "--format", "obj"]) == 2  # beside the result
    assert "export writes beside the result unless given --out" in capsys.readouterr().err


def test_export_out_where_no_folder_can_be_made(run, capsys):
    assert main(["export", str(run), "--format", "pc2", "--out", "/proc/casadi_keyframe"]) == 2
    err = capsys.readouterr().err
    assert "cannot write the output folder /proc/casadi_keyframe (--out)" in err


def test_export_of_a_missing_result_creates_no_output_folder(tmp_path, capsys):
    assert main(["export", str(tmp_path / "a" / "b"), "--format", "pc2"]) == 2
    assert "neither a results folder nor a .npz file" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()


def test_render_into_a_read_only_folder_is_refused_before_reading(run, capsys, monkeypatch):
    _never_read(monkeypatch)
    _read_only(monkeypatch)
    assert main(["render", str(run)]) == 2
    err = capsys.readouterr().err
    assert f"cannot write the output folder {run} (the results folder)" in err
    assert "render the copy" in err


def test_an_empty_out_is_refused(capsys):
    assert main(["solve", "flock_path", "--out", ""]) == 2
    assert "--out is empty" in capsys.readouterr().err


@pytest.mark.parametrize("checkpoint, words", [
    ("{tmp}", "is a folder: give a file path inside it"),
    ("{tmp}/a_file/best.npz", "a_file is a file, not a folder"),
    ("/proc/casadi_keyframe/best.npz", "(checkpoint=): "),
    ("", "is not a file name"),
])
def test_an_unwritable_checkpoint_is_refused_before_the_search(checkpoint, words, tmp_path,
                                                              monkeypatch):
    (tmp_path / "a_file").write_text("")
    prob = load_problem("flock_path", agents=4, steps=10)
    monkeypatch.setattr(type(prob), "simulate", lambda *a, **k: pytest.fail("simulated"))
    with pytest.raises(ValueError, match="checkpoint=") as err:
        solve(prob, maxiter=2, quiet=True, checkpoint=checkpoint.format(tmp=tmp_path))
    assert words in str(err.value)
    with pytest.raises(TypeError, match="checkpoint= is a file path"):
        solve(prob, maxiter=2, quiet=True, checkpoint=3)


def test_export_in_python_checks_its_out(run, tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(ValueError, match="cannot write the output folder"):
        export(run, "pc2", out=tmp_path / "f" / "x")
    assert export(run, "obj", out=tmp_path / "new")[0].is_file()
    np.testing.assert_equal(sorted(p.name for p in (tmp_path / "new").iterdir()), ["obj"])


def test_a_sweep_in_python_checks_its_out_before_any_point(tmp_path):
    pytest.importorskip("distributed")
    from casadi_keyframe.sweep import sweep

    (tmp_path / "f").write_text("")
    with pytest.raises(ValueError, match=r"cannot write the output folder .*f/s \(out=\)"):
        sweep("flock_path", {"weight": [1.0, 2.0]}, out=tmp_path / "f" / "s",
              overrides={"agents": 3, "steps": 5}, progress=False)
