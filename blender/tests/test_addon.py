"""The add-on headless in a real Blender: installed from its zip, Solve on a small sheet with
a wave shape key and a fold shape key, and the Mesh Cache it leaves hits both shapes within
the add-on's tolerance at their frames, at the scene's frame rate."""
import shutil
import sys
from pathlib import Path

import numpy as np

from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, wave

from conftest import REPORT, run_blender

EXECUTABLE = shutil.which("casadi-keyframe") or str(Path(sys.executable).with_name("casadi-keyframe"))


def test_addon_solves_onto_the_shape_keys(tmp_path, addon_zip):
    vertices, quads = hanging_sheet(6, 6, 0.8)
    job = {"addon": addon_zip, "executable": EXECUTABLE, "fps": 30, "start": 1,
           "vertices": vertices.tolist(), "quads": quads.tolist(),
           "wave": wave(vertices).tolist(), "fold": fold(vertices, 0.35, 0.12).tolist(),
           "wave_frame": 16, "fold_frame": 31, "pins": [0, 5], "location": [0.3, -0.2, 1.5],
           "tolerance": 0.01, "maxiter": 20, "folder": str(tmp_path / "work")}
    seen = run_blender("bl_addon.py", job, tmp_path)
    assert seen["operator"] == ["FINISHED"], seen
    assert seen["fps"] == 30 and seen["frame_end"] >= 31
    assert seen["modifiers"] == [["MESH_CACHE", 1.0]]
    rms = {}
    for name in ("wave", "fold"):
        got, want = (np.array(seen[name][k]) for k in ("animated", "target"))
        rms[name] = float(np.sqrt(np.mean(np.sum((got - want) ** 2, axis=1))))
        assert rms[name] <= job["tolerance"], (name, rms[name])
    assert seen["misses"].count(": hit") == 2, seen["misses"]
    REPORT.append(f"  add-on headless (6 x 6 sheet at (0.3, -0.2, 1.5), 30 fps, shape keys at "
                  f"frames 16 and 31): Mesh Cache vs shape keys rms wave {1e3 * rms['wave']:.3g} "
                  f"mm, fold {1e3 * rms['fold']:.3g} mm; the add-on reported: {seen['misses']}")
