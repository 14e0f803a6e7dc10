"""Pictures that show whether keyframes were hit: each keyframe panel seen from a camera
that shows its target's extent (not edge-on), the cloth coloured by its distance to the
target with a colour bar in mm, targets only at their own frame (or labelled with it); a
convergence plot whose lines stay readable, whose stages are labelled and whose wild
iterates do not squash the rest."""
import importlib
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from casadi_keyframe import ControlProblem, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.render import cloth as render_cloth
from casadi_keyframe.render.targets import extent_seen, target_camera
from casadi_keyframe.views import ClothView

render_convergence = importlib.import_module("casadi_keyframe.render.convergence")  # the module
CAMERA = (15.0, -30.0)  # cloth_shapes' camera, which sees its frame-4 target edge-on


@pytest.fixture(scope="module")
def sheet():
    """A 4 x 4 sheet hanging in the plane y = 0; at frame 4 its target is the sheet turned
    flat (z = const), which the camera at 15 degrees elevation sees nearly edge-on."""
    model = ClothModel.grid(4, 4, pinned=[0, 3])
    x0 = model.rest_positions
    flat = np.c_[x0[:, 0], -x0[:, 2], np.full(len(x0), x0[:, 2].max())]
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler(), x0=x0,
                          v0=np.zeros_like(x0), steps=6, dt=1 / 30, controls=StepForces(),
                          objective=StateKeyframe(4, x=flat) + StateKeyframe(6, x=x0),
                          name="sheet", view=ClothView(camera=CAMERA))
    return prob, prob.simulate()


def test_a_flat_target_is_not_seen_edge_on(sheet):
    prob, traj = sheet
    target = prob.objective_terms.markers()[0].points
    assert extent_seen(target, CAMERA) < 0.1  # the picture issue 26 found
    camera = render_cloth.keyframe_camera(prob, [4], traj)
    # a vertical sheet and a flat target: no camera sees both better than 0.5
    assert min(extent_seen(target, camera), extent_seen(traj.x[4], camera)) > 0.45
    assert target_camera([traj.x[6]], (15.0, -80.0)) == (15.0, -80.0)  # a good view is kept


def _figure_of(monkeypatch, module):
    """Run a picture function and keep its figure instead of writing it."""
    kept = {}
    monkeypatch.setattr(module, "save_figure", lambda fig, path, **kw: kept.setdefault("fig", fig))
    monkeypatch.setattr(module.plt, "close", lambda fig=None: None)
    return kept


def test_keyframe_panels_colour_the_distance_and_draw_targets_at_their_frame(sheet, tmp_path,
                                                                            monkeypatch):
    prob, traj = sheet
    kept = _figure_of(monkeypatch, render_cloth)
    render_cloth.snapshot(prob, traj, tmp_path / "k.png")
    fig = kept["fig"]
    panels = [ax for ax in fig.axes if ax.name == "3d"]
    titles = [ax.get_title() for ax in panels]
    assert titles[0].startswith("frame 0 /") and titles[1].startswith("frame 4 /")
    said = [[t.get_text() for t in ax.texts] for ax in panels]
    assert said[0] == []  # frame 0 has no keyframe: nothing to judge, no target drawn
    assert len(said[1]) == 1 and "StateKeyframe@4" in said[1][0]
    assert "rms miss" in said[1][0] and "mm (tol" in said[1][0]
    wireframes = [[c for c in ax.collections if isinstance(c, Poly3DCollection)
                   and len(c.get_facecolor()) == 0] for ax in panels]
    assert wireframes[0] == [] and len(wireframes[1]) == 1  # no target at frame 0
    assert not any("target at frame" in t for s in said for t in s)  # not in a snapshot
    faces = len(prob.model.faces)
    cloth = [next(c for c in ax.collections if isinstance(c, Poly3DCollection)
                  and len(c.get_facecolor()) == faces) for ax in panels]
    hues = [{tuple(np.round(c / max(c.max(), 1e-9), 2)) for c in f.get_facecolor()[:, :3]}
            for f in cloth]
    assert len(hues[0]) == 1 and len(hues[1]) > 1  # one cloth colour, then distances
    assert panels[1].azim != CAMERA[1] or panels[1].elev != CAMERA[0]
    bars = [ax for ax in fig.axes if "[mm]" in ax.get_xlabel()]
    assert len(bars) == 1
    monkeypatch.undo()
    matplotlib.pyplot.close(fig)


def test_the_animation_labels_a_target_drawn_before_its_frame(sheet):
    prob, traj = sheet
    fig = matplotlib.pyplot.figure()
    panel = render_cloth.TrajectoryPanel(fig.add_subplot(projection="3d"), prob, traj)
    panel.draw(1, hold=True)
    assert [t.get_text() for t in panel.ax.texts] == ["target at frame 4"]
    panel.draw(4, hold=True)
    texts = [t.get_text() for t in panel.ax.texts]
    assert len(texts) == 1 and "StateKeyframe@4" in texts[0]
    panel.draw(5, hold=True)  # the verdict stays until the next keyframe
    texts = [t.get_text() for t in panel.ax.texts]
    assert "target at frame 6" in texts and any("StateKeyframe@4" in t for t in texts)
    matplotlib.pyplot.close(fig)


def _history(objective, keyframe, particles, stage):
    return [{"iteration": i + 1, "seconds": float(i), "objective": f, "keyframe_error": k,
             "particles": p, "stage": s, "dt": 0.02}
            for i, (f, k, p, s) in enumerate(zip(objective, keyframe, particles, stage))]


def test_convergence_labels_stages_and_keeps_wild_iterates_off_the_scale(tmp_path,
                                                                        monkeypatch):
    kept = _figure_of(monkeypatch, render_convergence)
    objective = [5.0, 1.0, 0.5, 6e7, 0.4, 0.9, 0.3]
    keyframe = [4.9, 0.9, 0.0, 6e7, 0.3, 0.8, 0.2]
    result = SimpleNamespace(history=_history(objective, keyframe, [36] * 5 + [144] * 2,
                                              [0] * 5 + [1] * 2),
                             start={"objective": 10.0, "keyframe_error": 9.9},
                             method="ipopt", gradient="adjoint")
    render_convergence.convergence(result, tmp_path / "c.png")
    fig = kept["fig"]
    left = fig.axes[0]
    assert [t.get_text().strip() for t in left.texts] == ["stage 1: 144 particles"]
    assert left.get_ylim()[1] < 1e3  # the 6e7 iterate does not squash the rest
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels[:3] == ["objective", "keyframe error", "control cost"]
    assert "iterate above 10x the start (off the scale)" in labels
    assert "keyframe error 0 (every keyframe met)" in labels
    notes = " ".join(t.get_text() for t in fig.texts)
    assert "up to 6e+07" in notes and "stage begins" in notes
    widths = {line.get_label(): line.get_linewidth() for line in left.lines}
    assert widths["objective"] > widths["keyframe error"]  # the thin line drawn over it
    monkeypatch.undo()
    matplotlib.pyplot.close(fig)
