"""A cloth (USD, PC2, Alembic) and a flock (USD PointInstancer) exported by the library and
opened in a real Blender: the positions at several frames equal result.npz, the scene runs
at the result's frame rate over its frame range, and the flock has one instance per agent
(the highlighted one of its own prototype)."""
import os
import sys

import numpy as np
import pytest

from casadi_keyframe import cli, load_problem
from casadi_keyframe.export import export

from conftest import REPORT, blender_command, run_blender

FRAMES = [0, 1, 40, 80]


def solve(tmp_path_factory, name, *sets):
    out = tmp_path_factory.mktemp(name)
    args = ["solve", name, *[a for s in sets for a in ("--set", s)], "--maxiter", "2",
            "--quiet", "--no-animation", "--no-viewer", "--out", str(out)]
    assert cli.main(args) in (0, 1, 3)
    return out, np.load(out / "result.npz")


def test_cloth_usd_pc2_and_alembic_in_blender(tmp_path_factory, tmp_path, addon_zip,
                                              monkeypatch):
    blender = blender_command()
    out, result = solve(tmp_path_factory, "mesh_keyframes")
    (usd,), (pc2, rest) = export(out, "usd"), export(out, "pc2")
    monkeypatch.setenv("CASADI_KEYFRAME_BLENDER", blender[0])
    (abc,) = export(out, "abc")
    rate = 1 / float(result["dt"])
    seen = run_blender("bl_roundtrip.py", {"frames": FRAMES, "usd": str(usd), "pc2": str(pc2),
                                           "rest": str(rest), "abc": str(abc),
                                           "fps": round(rate), "addon": addon_zip}, tmp_path)
    x, last = result["x"], result["x"].shape[0] - 1
    errors = {}
    for fmt in ("usd", "pc2", "abc"):
        errors[fmt] = max(np.abs(np.array(seen[fmt]["frames"][str(f)]) - x[f]).max()
                          for f in FRAMES)
        assert errors[fmt] < 1e-6, (fmt, errors[fmt])  # float32 files
    assert not np.allclose(seen["usd"]["frames"]["1"], seen["usd"]["frames"]["80"])
    for fmt in ("usd", "abc"):
        assert seen[fmt]["fps"] == pytest.approx(rate)
        assert (seen[fmt]["frame_start"], seen[fmt]["frame_end"]) == (0, last)
    alone = seen["usd_importer_alone"]
    REPORT.append(f"Blender {seen['blender']} (Python {sys.version.split()[0]} bpy venv: "
                  f"{os.environ.get('BLENDER_PYTHON')}); cloth {x.shape[1]} vertices, frames "
                  f"0..{last}, result at {rate:g} fps")
    for fmt in ("usd", "pc2", "abc"):
        extra = (f", scene {seen[fmt]['fps']:g} fps, frames {seen[fmt]['frame_start']}.."
                 f"{seen[fmt]['frame_end']}" if fmt != "pc2" else ", Mesh Cache frame start 1")
        REPORT.append(f"  cloth {fmt}: largest |Blender - result.npz| over frames {FRAMES} = "
                      f"{errors[fmt]:.2e} m{extra}")
    REPORT.append(f"  USD importer alone: frames {alone['frame_start']}..{alone['frame_end']} "
                  f"at {alone['fps']:g} fps (the add-on's import sets the rate)")


def test_flock_point_instancer_in_blender(tmp_path_factory, tmp_path, addon_zip):
    out, result = solve(tmp_path_factory, "flock_race", "agents=8", "steps=12")
    (usd,) = export(out, "usd")
    frames = [0, 5, 12]
    seen = run_blender("bl_roundtrip.py", {"frames": frames, "flock": str(usd),
                                           "addon": addon_zip}, tmp_path)["flock"]
    highlight = load_problem("flock_race", agents=8, steps=12).view.highlight
    x, v = result["x"], result["v"]
    worst = 0.0
    for f in frames:
        inst = seen["frames"][str(f)]
        assert len(inst) == 8
        got = np.array([i["position"] for i in inst])
        order = [int(np.argmin(np.linalg.norm(got[:, :2] - p, axis=1))) for p in x[f]]
        assert sorted(order) == list(range(8))  # one instance per agent
        worst = max(worst, np.abs(got[order, :2] - x[f]).max())
        assert worst < 1e-5 and np.allclose(got[:, 2], 0)
        protos = [inst[k]["proto"] for k in order]
        assert [a for a, p in enumerate(protos) if p.startswith("Highlighted")] == list(highlight)
        heading = np.array([inst[k]["heading"] for k in order])[:, :2]
        unit = v[f] / np.linalg.norm(v[f], axis=1, keepdims=True)
        cosine = np.sum(heading * unit, axis=1) / np.linalg.norm(heading, axis=1)
        assert cosine.min() > 0.999
    assert seen["fps"] == pytest.approx(1 / float(result["dt"]))
    assert (seen["frame_start"], seen["frame_end"]) == (0, x.shape[0] - 1)
    REPORT.append(f"  flock USD PointInstancer: 8 instances at frames {frames}, largest position "
                  f"error {worst:.2e} m, highlighted agents {list(highlight)} on their own "
                  f"prototype, headings along v; scene {seen['fps']:g} fps, frames "
                  f"{seen['frame_start']}..{seen['frame_end']}")
