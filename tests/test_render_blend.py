"""Blend rendering (fig. 6): fall clip, optimised blend and walk clip side by side."""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from casadi_keyframe import load_problem, render  # noqa: E402
from casadi_keyframe.render import blend as render_blend  # noqa: E402
from casadi_keyframe.render import select_frames, write_gif  # noqa: E402
from casadi_keyframe.render.cloth import CLOTH, back_color, face_colors  # noqa: E402

TITLES = ("fall (source clip)", "blend (optimised)", "walk (source clip)")


@pytest.fixture(scope="module")
def blend():
    p = load_problem("cape_blend", rows=8, cols=6, window=0.5, guess="passive")
    return p, p.simulate()


def test_clip_frames_follow_the_blend(blend):
    p, traj = blend
    fall, walk = p.view.fall.trajectory, p.view.walk.trajectory
    a, b = round(p.view.t_a / p.dt), round(p.view.t_b / p.dt)
    for k in (-render_blend.lead_in(p), -1, 0, 7, p.steps):
        assert render_blend.clip_frame(p, "fall", k) == a + k
        assert render_blend.clip_frame(p, "walk", k) == b + k
        np.testing.assert_array_equal(render_blend.shown(p, traj, "fall", k).x, fall.x[a + k])
        np.testing.assert_array_equal(render_blend.shown(p, traj, "walk", k).x, walk.x[b + k])
        assert render_blend.shown(p, traj, "walk", k).t == pytest.approx((b + k) * walk.dt)
        middle = render_blend.shown(p, traj, "blend", k)
        np.testing.assert_array_equal(middle.x, traj.x[k] if k >= 0 else fall.x[a + k])
        assert middle.model is (p.model if k >= 0 else p.view.fall.model)
    np.testing.assert_array_equal(traj.x[0], fall.x[a])  # the blend starts on the fall
    with pytest.raises(ValueError):
        render_blend.shown(p, traj, "walk", -b - 1)


def test_lead_in_fits_both_clips(blend):
    p, _ = blend
    assert render_blend.lead_in(p) == round(render_blend.LEAD_IN / p.dt)
    assert render_blend.lead_in(p, 10.0) == round(p.view.t_b / p.dt)  # walk starts sooner
    ks = render_blend.blend_frames(p)
    assert ks[0] == -render_blend.lead_in(p) and ks[-1] == p.steps


def _cape_rgb(panel):
    """Mean RGB of the cape the panel drew: the first faces of the colours it gave its
    surfaces (cape, then bodies), which the collection drew (depth sorting only reorders)."""
    drawn = panel.dynamic[0].get_facecolor()[:, :3].mean(0)
    np.testing.assert_allclose(drawn, panel.colors[:, :3].mean(0))
    return panel.colors[:len(panel.model.faces), :3].mean(0)


def _front_rgb(panel):
    """Mean RGB of the cape's faces turned towards the camera (the back side is tinted)."""
    colors, away = panel.colors[:len(panel.model.faces), :3], panel.facing_away
    return colors[~away].mean(0) if (~away).any() else colors.mean(0)


def test_blend_highlighted_sources_plain(blend):
    p, traj = blend
    fig = plt.figure()
    try:
        panels = render_blend.side_by_side(fig, p, traj, render_blend.blend_frames(p))
        for k in (-3, 0, p.steps // 2, p.steps):
            for panel in panels:
                panel.draw(k)
                s = render_blend.shown(p, traj, panel.panel, k)
                want = face_colors(s.x, s.model.faces, s.color, back=back_color(s.color),
                                   eye=panel.eye)[:, :3].mean(0)
                np.testing.assert_allclose(_cape_rgb(panel), want)
            fall, middle, walk = (_front_rgb(panel) for panel in panels)
            assert fall[2] > fall[0] and walk[2] > walk[0]  # blue cloth
            if k >= 0:
                assert middle[0] > middle[2]  # orange during the blend
            else:
                np.testing.assert_allclose(middle, fall)  # the lead-in is the fall clip
        assert render_blend.BLEND != CLOTH
    finally:
        plt.close(fig)


def test_animate_dispatches_and_writes_three_panels(blend, tmp_path, monkeypatch):
    p, traj = blend
    seen = {}

    def spy(fig, draw, frames, path, fps, **bounds):
        write_gif(fig, draw, frames, path, fps, **bounds)
        seen.update(frames=list(frames), axes=[(ax.name, ax.get_title()) for ax in fig.axes],
                    legend=[t.get_text() for t in fig.legends[0].get_texts()])

    monkeypatch.setattr(render_blend, "write_gif", spy)
    out = render.animate(p, traj, tmp_path / "blend.gif", max_frames=4, title="fig6")
    lead, last = render_blend.lead_in(p), render_blend.lead_in(p) + p.steps
    assert seen["frames"] == select_frames(last, [lead], 4)
    assert lead in seen["frames"] and last in seen["frames"]
    with Image.open(out) as im:
        assert im.n_frames == len(seen["frames"])
    assert [name for name, _ in seen["axes"]] == ["3d"] * 3
    for (_, title), want in zip(seen["axes"], TITLES):
        assert title.startswith(want) and " s" in title
    assert "t = 0.50 s of 0.50 s" in seen["axes"][1][1]  # ends on the blend's last frame
    assert {"cloth (front)", "cloth (back)", "blend (optimised)",
            "keyframe shape (at its frame)"} <= set(
        seen["legend"])
    assert "keyframe target" not in seen["legend"]  # the shape is a wireframe, not crosses


def test_snapshot_dispatches(blend, tmp_path):
    p, traj = blend
    out = render.snapshot(p, traj, tmp_path / "blend.png")
    with Image.open(out) as im:
        assert im.format == "PNG"
    with pytest.raises(ValueError):
        render.snapshot(p, traj, tmp_path / "bad.png", frames=[0, p.steps + 1])
