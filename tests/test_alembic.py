"""Alembic export's refusals: with no Blender a one-line error names both ways to get one; a
Blender built without Alembic (Debian's) is named; a flock is refused.  The round trip
through a real Blender is in ``make test-blender``."""
import shutil

import pytest

from casadi_keyframe import cli
from casadi_keyframe.export import alembic


def test_no_blender_is_one_line_naming_both_ways(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(alembic.importlib.util, "find_spec", lambda name: None)
    monkeypatch.setattr(alembic.shutil, "which", lambda name: None)
    monkeypatch.delenv("CASADI_KEYFRAME_BLENDER", raising=False)
    assert cli.main(["export", str(tmp_path), "--format", "abc"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "pip install bpy" in err and "'blender' is on the PATH" in err


def test_a_named_blender_that_is_missing(monkeypatch):
    monkeypatch.setattr(alembic.importlib.util, "find_spec", lambda name: None)
    monkeypatch.setenv("CASADI_KEYFRAME_BLENDER", "/nowhere/blender")
    with pytest.raises(ImportError, match="/nowhere/blender was not found"):
        alembic.find_blender()


def test_a_flock_has_no_alembic(tmp_path):
    from casadi_keyframe.export.scene import Scene
    import numpy as np
    scene = Scene("flock", 0.1, np.zeros((2, 3, 3)), None, [], [])
    with pytest.raises(ValueError, match="Alembic export is for cloth.*PointInstancer"):
        alembic.write_alembic(scene, tmp_path / "f.abc")


@pytest.mark.skipif(shutil.which("blender") is None, reason="no blender binary")
def test_debian_blender_without_alembic_is_named(monkeypatch, tmp_path):
    import numpy as np
    from casadi_keyframe.export.scene import Scene
    monkeypatch.setattr(alembic.importlib.util, "find_spec", lambda name: None)
    monkeypatch.delenv("CASADI_KEYFRAME_BLENDER", raising=False)
    x = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]] * 3)
    scene = Scene("tri", 1 / 30, x, np.array([[0, 1, 2]]), [], [])
    try:
        path = alembic.write_alembic(scene, tmp_path / "tri.abc")
    except ImportError as err:  # Debian's 3.4
        assert "built without Alembic" in str(err) and "pip install bpy" in str(err)
    else:
        assert path.stat().st_size > 0
