"""Damaged files given to every command that reads them: one line naming the file, what is
wrong with it and what to do, exit code 2, never a traceback, never advice to unpickle."""
import io
import json
import zipfile

import numpy as np
import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.saved import FileDamaged, read_json, read_npz
from casadi_keyframe.saved import read_run

SMALL = ["flock_path", "--set", "agents=4", "--set", "steps=10"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A small solved run: result.npz, checkpoint.npz, summary.json."""
    out = tmp_path_factory.mktemp("run")
    assert main(["solve", *SMALL, "--maxiter", "2", "--out", str(out), "--quiet",
                 "--no-animation", "--no-viewer"]) in (0, 3)
    return out


def _rewritten(data: dict, **changes) -> bytes:
    """An npz of ``data`` with ``changes`` (None drops an array), as bytes."""
    arrays = {k: v for k, v in {**data, **changes}.items() if v is not None}
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def damages(good: bytes, data: dict) -> dict:
    """Damaged versions of a good npz file: name -> (bytes, words the message must hold)."""
    zipped = io.BytesIO()
    with zipfile.ZipFile(zipped, "w") as z:
        z.writestr("notes.txt", "hello")
    npy = io.BytesIO()
    np.save(npy, data["u"])
    middle = bytearray(good)
    middle[len(good) // 2: len(good) // 2 + 64] = bytes(64)  # zeros over some data
    meta = dict(data)
    return {
        "empty": (b"", "is empty (0 bytes)"),
        "truncated": (good[: len(good) // 2], "is truncated"),
        "random bytes": (bytes(np.random.default_rng(0).integers(0, 256, 5000, np.uint8)),
                         "is not an npz file"),
        "an npy file": (npy.getvalue(), "single numpy array (.npy)"),
        "a zip of text": (zipped.getvalue(), "member 'notes.txt' is not a numpy array"),
        "pickled objects": (_rewritten(data, u=np.array([{"a": 1}], dtype=object)),
                            "holds Python objects in array 'u'"),
        "no controls": (_rewritten(data, u=None), "is missing array 'u'"),
        "text controls": (_rewritten(data, u=np.array(["a", "b"])),
                          "array 'u' that is not 1-D finite real numbers"),
        "meta not JSON": (_rewritten(meta, meta=np.array("{oops")),
                          "'meta' that is not valid JSON"),
        "meta without problem": (_rewritten(meta, meta=np.array(json.dumps([1, 2]))),
                                 "'meta' that does not name its problem"),
        "zeroed bytes": (bytes(middle), "damaged array"),
    }


def _data(path) -> dict:
    with np.load(path) as d:
        return {k: d[k] for k in d.files}


@pytest.mark.parametrize("name", ["result.npz", "checkpoint.npz"])
@pytest.mark.parametrize("command", ["render", "export", "resume"])
def test_every_command_names_the_damage_of_every_run_file(name, command, run, tmp_path,
                                                           capsys):
    good = (run / name).read_bytes()
    for damage, (content, words) in damages(good, _data(run / name)).items():
        if damage == "zeroed bytes" and name == "result.npz":
            continue  # compressed: the zeros may fall in a member or in the directory
        target = tmp_path / damage.replace(" ", "_")
        target.mkdir()
        (target / name).write_bytes(content)
        args = {"render": ["render", str(target / name), "--no-animation"],
                "export": ["export", str(target / name), "--format", "pc2"],
                "resume": ["solve", *SMALL, "--out", str(tmp_path / "o"), "--quiet",
                           "--resume", str(target / name)]}[command]
        assert main(args) == 2, damage
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1, (damage, err)
        assert str(target / name) in err and words in err, (damage, err)
        assert "allow_pickle" not in err and "Traceback" not in err
        assert "solve" in err.split(";")[-1], err  # what to do


def test_a_damaged_result_points_to_the_checkpoint_beside_it(run, tmp_path, capsys):
    (tmp_path / "checkpoint.npz").write_bytes((run / "checkpoint.npz").read_bytes())
    (tmp_path / "result.npz").write_bytes((run / "result.npz").read_bytes()[:1000])
    assert main(["render", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"give the run's other file {tmp_path / 'checkpoint.npz'}" in err


def test_a_trajectory_that_does_not_fit_its_problem_is_refused(run, tmp_path, capsys):
    data = _data(run / "result.npz")
    (tmp_path / "result.npz").write_bytes(_rewritten(data, x=data["x"][:-1], v=data["v"][:-1]))
    assert main(["export", str(tmp_path), "--format", "obj"]) == 2
    assert "holds a trajectory of shape (10, 4, 2)" in capsys.readouterr().err
    assert main(["solve", *SMALL, "--out", str(tmp_path / "o"), "--quiet", "--resume",
                 str(tmp_path / "result.npz")]) == 2
    assert "holds a trajectory of shape (10, 4, 2)" in capsys.readouterr().err
    (tmp_path / "result.npz").write_bytes(_rewritten(data, v=data["v"][:, :2]))
    assert main(["render", str(tmp_path)]) == 2
    assert "trajectory that does not fit together" in capsys.readouterr().err


def test_history_arrays_of_different_lengths_are_refused(run, tmp_path):
    data = _data(run / "result.npz")
    (tmp_path / "result.npz").write_bytes(
        _rewritten(data, history_seconds=np.r_[data["history_seconds"], 1.0]))
    with pytest.raises(FileDamaged, match="history arrays of different lengths"):
        read_run(tmp_path / "result.npz")


def test_a_damaged_summary_beside_an_old_result_is_named(run, tmp_path):
    """A result written before files carried meta is read with summary.json's."""
    (tmp_path / "result.npz").write_bytes(_rewritten(_data(run / "result.npz"), meta=None))
    (tmp_path / "summary.json").write_text('{"problem": "flock_path", "overr')
    with pytest.raises(FileDamaged, match=r"summary.json is truncated \(its JSON ends early\)"):
        read_run(tmp_path / "result.npz")


def test_the_readers_never_unpickle(tmp_path):
    np.savez(tmp_path / "objects.npz", u=np.array([object()], dtype=object))
    with pytest.raises(FileDamaged, match="holds Python objects") as err:
        read_npz(tmp_path / "objects.npz")
    assert "allow_pickle" not in str(err.value)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_npz(tmp_path / "none.npz")
    (tmp_path / "bad.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(FileDamaged, match="is not a text file"):
        read_json(tmp_path / "bad.json")
    (tmp_path / "bad.json").write_text("[1, 2,, 3]")
    with pytest.raises(FileDamaged, match=r"is not valid JSON \(Expecting value at line 1\)"):
        read_json(tmp_path / "bad.json")


def test_a_damaged_sweep_row_is_named_and_its_point_solved_again(tmp_path, capsys):
    from casadi_keyframe.sweep.plan import _todo
    from casadi_keyframe.sweep.tasks import read_row

    specs = []
    for name, text in (("a", '{"point": "a", "status": "conver'), ("b", "[1, 2]"), ("c", None)):
        (tmp_path / name).mkdir()
        if text is not None:
            (tmp_path / name / "row.json").write_text(text)
        specs.append({"folder": str(tmp_path / name), "id": name})
    with pytest.raises(FileDamaged, match=r"row.json is truncated .*the point is solved again"):
        read_row(tmp_path / "a")
    assert read_row(tmp_path / "c") is None
    with pytest.raises(ValueError, match="already holds a sweep's points: give --resume"):
        _todo(specs, resume=False)
    todo, stale = _todo(specs, resume=True)
    assert [s["id"] for s in todo] == ["a", "b", "c"] and stale == 0
    out = capsys.readouterr().out
    assert f"sweep: {tmp_path / 'a' / 'row.json'} is truncated" in out
    assert "is not a sweep point's row" in out
