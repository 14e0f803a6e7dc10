"""The HTML viewer (issue 15): one self-contained page per result, written after a solve,
that a browser opens offline and without console errors."""
import shutil
import subprocess
import sys

import numpy as np
import pytest

from casadi_keyframe import cli, load_problem
from casadi_keyframe.export import scene_of

pytest.importorskip("plotly", reason="the viewer needs plotly: pip install casadi_keyframe[viewer]")
from casadi_keyframe.export.viewer import equal_boxes, figure, panels  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# Chromium's own performance hints, logged like console messages: software WebGL's stalls,
# and plotly.js reading a canvas back (Chromium suggests willReadFrequently)
BROWSER_NOTES = ("GL Driver Message", "Canvas2D: Multiple readback operations")


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("toss")
    code = cli.main(["solve", "cloth_toss", "--set", "rows=4", "--set", "cols=4", "--set",
                     "steps=10", "--maxiter", "1", "--quiet", "--no-animation", "--out",
                     str(out)])
    assert code in (0, 3)
    return out


def test_solve_writes_a_self_contained_viewer(solved):
    page = (solved / "viewer.html").read_text()
    assert "window.Plotly" in page or "Plotly.newPlot" in page
    assert "<script src=" not in page and 'src="http' not in page  # opens offline


def test_frames_caption_and_toggles():
    p = load_problem("cloth_toss", rows=4, cols=4, steps=10, ring_at=0.4)  # the ring at frame 4
    traj = p.simulate(records=False)
    fig = figure(scene_of(p, traj))
    assert len(fig.frames) == traj.steps + 1
    captions = [f.layout.annotations[-1].text for f in fig.frames]
    assert "frame 4 / 10" in captions[4] and "t = 0.067 s" in captions[4]
    assert "keyframe: CenterOfMass@4 position_error" in captions[4]
    assert "keyframe" not in captions[3]
    stretch = p.model.max_stretch(traj.x[4])
    assert f"largest stretch {stretch:.3g}" in captions[4]
    labels = [b.label for menu in fig.layout.updatemenus for b in menu.buttons]
    assert {"\u25b6 play", "targets on/off", "colliders on/off", "trails on/off"} <= set(labels)
    moved = fig.frames[7].data[0]
    np.testing.assert_array_equal(moved.x, traj.x[7, :, 0].astype(np.float32))


def test_blend_panels_share_their_scale():
    p = load_problem("cape_blend", rows=6, cols=5, window=0.2, guess="passive")
    scene = scene_of(p, p.simulate(records=False))
    plist = panels(scene)
    assert [q["title"].split()[0] for q in plist] == ["fall", "blend", "walk"]
    halves = [half for _, half in equal_boxes(plist)]
    assert all(np.array_equal(h, halves[0]) for h in halves)
    fig = figure(scene)
    assert fig.layout.scene3.xaxis.range is not None and len(fig.frames) == p.steps + 1


def test_solve_skips_the_viewer_without_plotly(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "plotly.graph_objects", None)
    assert cli.main(["solve", "cloth_toss", "--set", "rows=3", "--set", "cols=3", "--set",
                     "steps=6", "--maxiter", "1", "--quiet", "--no-animation", "--out",
                     str(tmp_path)]) in (0, 3)
    assert "viewer skipped" in capsys.readouterr().out and not (tmp_path / "viewer.html").exists()
    assert cli.main(["export", str(tmp_path), "--format", "html"]) == 2
    assert "pip install casadi_keyframe[viewer]" in capsys.readouterr().err


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian: apt-get "
                                             "install chromium); the page-load check needs it")
@pytest.mark.parametrize("frame", [0, 4])
def test_the_page_loads_without_console_errors(solved, frame):
    run = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
                          "--enable-logging=stderr", "--v=0", "--virtual-time-budget=5000",
                          "--dump-dom", f"file://{solved / 'viewer.html'}#frame={frame}"],
                         capture_output=True, text=True, timeout=120)
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line
               and not any(note in line for note in BROWSER_NOTES)]
    assert not console, console
    assert f"frame {frame} / 10" in run.stdout  # the page drew, at the frame asked for


@pytest.mark.parametrize("name, overrides", [("cloth_toss", {"rows": 4, "cols": 4, "steps": 10,
                                                             "ring_at": 0.4}),
                                             ("flock_shapes", {"agents": 4, "steps": 10})])
def test_targets_are_named_with_their_frame_and_faint_elsewhere(name, overrides):
    """Every target is drawn whole only at its own frame, named "target at frame N", and the
    legend sits below the controls, over no data (issue 26: it hid part of the flock)."""
    p = load_problem(name, **overrides)
    fig = figure(scene_of(p, p.simulate(records=False)))
    named = {t.name: i for i, t in enumerate(fig.data) if t.name.startswith("target at frame")}
    assert set(named) == {f"target at frame {m.frame} ({m.label})"
                          for m in p.objective_terms.markers()}
    for trace_name, index in named.items():
        frame = int(trace_name.split()[3])
        opacity = {n: next(d.opacity for d, i in zip(f.data, f.traces) if i == index)
                   for n, f in enumerate(fig.frames)}
        assert opacity[frame] == 1.0 and max(o for n, o in opacity.items() if n != frame) < 0.5
    assert fig.layout.legend.orientation == "h" and fig.layout.legend.y < 0
