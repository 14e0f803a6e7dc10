"""Matplotlib figures and animations of flock trajectories, seen from above (x, y).

``animate`` writes a GIF, ``snapshot`` a PNG of small multiples at the keyframes and
``convergence`` a PNG of the optimizer's history.  All use the Agg backend and close their
figures, and write each file to a temporary name moved into place when complete, so an
interrupted drawing leaves no half-written picture.  For a cloth (a model with ``faces``)
``animate`` and ``snapshot`` hand over to :mod:`.render_cloth`, which draws in 3-D, and for
a blend between source clips (a scene with ``clips``) to :mod:`.render_blend`, which draws
the clips and the blend side by side.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.animation import PillowWriter  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.patches import Polygon  # noqa: E402

from .interrupts import check  # noqa: E402
from .io import atomic_path  # noqa: E402
from .objectives import CenterOfMassKeyframe, RegionTarget, StateKeyframe  # noqa: E402

AGENT, HIGHLIGHT, REGION, COM, PARTICLE = "#4c72b0", "#e1812c", "#3a923a", "#7b4ea3", "#c03d3e"
TRAIL, NEAR = 10, 3  # trail length and "near the keyframe" window, in frames
_rgb = matplotlib.colors.to_rgb


def keyframes(problem) -> list[int]:
    """Sorted distinct frames at which the problem's state terms are active."""
    return sorted({int(t.frame) for t in problem.objective_terms.state_terms})


def select_frames(steps: int, required=(), max_frames: int = 150) -> list[int]:
    """Frames ``0..steps`` to show: all if few, else ~``max_frames + 1`` evenly spaced.

    Frame 0, the last frame and every ``required`` frame are always included.
    """
    if steps <= max_frames:
        return list(range(steps + 1))
    must = {0, steps} | {int(f) for f in required if 0 <= f <= steps}
    grid = set(np.round(np.linspace(0, steps, max(max_frames, 1) + 1)).astype(int).tolist())
    for f in sorted(must - grid):  # swap the nearest free grid frame for each missing one
        free = grid - must
        if free:
            grid.remove(min(free, key=lambda g: abs(g - f)))
        grid.add(f)
    return sorted(grid)


def snapshot_frames(problem, trajectory, frames=None, most: int = 6) -> list[int]:
    """Frames of a snapshot: by default the first, each keyframe and the last.

    At most ``most``: longer lists keep their first and last frame and are thinned evenly.
    """
    frames = sorted({0, trajectory.steps, *keyframes(problem)} if frames is None
                    else {int(f) for f in frames})
    if not frames or frames[0] < 0 or frames[-1] > trajectory.steps:
        raise ValueError(f"snapshot frames must be in 0..{trajectory.steps}, got {frames}")
    if len(frames) > most:
        frames = [frames[i] for i in np.round(np.linspace(0, len(frames) - 1, most)).astype(int)]
    return frames


def frame_title(name: str, n: int, traj, full: bool = True) -> str:
    """``"name - frame n / steps  t = ...s"`` (without the name if not ``full``)."""
    txt = f"frame {n} / {traj.steps}  t = {n * traj.dt:.2f}s"
    return f"{name} \u2014 {txt}" if full else txt


def write_gif(fig, draw, frames, path: Path, fps: int, dpi: int = 80) -> None:
    """Grab ``fig`` after ``draw(n)`` for each of ``frames`` into a GIF at ``path``.

    Written whole or not at all: an interrupted animation leaves no truncated GIF (and the
    frames grabbed so far are dropped, not encoded)."""
    writer = PillowWriter(fps=fps)
    with atomic_path(path) as tmp, matplotlib.rc_context({"savefig.bbox": None}):
        writer.setup(fig, str(tmp), dpi=dpi)
        for n in frames:
            check()
            draw(n)
            writer.grab_frame()
        writer.finish()


def save_figure(fig, path, **kwargs) -> Path:
    """``fig.savefig`` through a temporary file moved into place (see :func:`.io.atomic_path`)."""
    check()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return Path(path)


def _renderer_3d(problem):
    """The module drawing ``problem`` in 3-D, or None (a flock, drawn here): render_blend
    for a blend between source clips (``scene["clips"]``), render_cloth for a cloth."""
    if "clips" in problem.scene:
        from . import render_blend
        return render_blend
    if hasattr(problem.model, "faces"):
        from . import render_cloth
        return render_cloth
    return None


class _Scene:
    """The artists of one top-down view; ``draw(n)`` updates them to frame ``n``."""

    def __init__(self, ax, problem, traj, *, name=None):
        self.ax, self.traj = ax, traj
        self.name = problem.name if name is None else name
        self.xy = np.asarray(traj.x)[:, :, :2]
        terms = problem.objective_terms.state_terms
        self.coms = sorted((t for t in terms if isinstance(t, CenterOfMassKeyframe)
                            and t.position_target is not None), key=lambda t: t.frame)
        self.regions = [t for t in terms if isinstance(t, RegionTarget)]
        self.states = [t for t in terms if isinstance(t, StateKeyframe) and t.position_target is not None]
        w = np.asarray(problem.model.masses, dtype=float)
        self.com = np.einsum("i,nij->nj", w / w.sum(), self.xy)
        self.hl = np.zeros(self.xy.shape[1], bool)
        self.hl[list(problem.scene.get("highlight", []))] = True
        self.trail_rgb = np.where(self.hl[:, None], _rgb(HIGHLIGHT), _rgb(AGENT))
        self._limits()
        self._build()

    def _limits(self):
        pts = np.vstack([self.xy.reshape(-1, 2), self.com]
                        + [np.atleast_2d(t.position_target)[:, :2] for t in self.coms + self.states]
                        + [t.shape.outline() for t in self.regions])
        lo, hi = pts.min(0), pts.max(0)
        pad = 0.06 * max(hi - lo) + 0.3
        self.ax.set_xlim(lo[0] - pad, hi[0] + pad)
        self.ax.set_ylim(lo[1] - pad, hi[1] + pad)
        self.ax.set_aspect("equal", adjustable="box")
        self.ax.tick_params(labelsize=7)
        self.ax.grid(alpha=0.15)

    def _build(self):
        ax = self.ax
        self.patches = []
        for t in self.regions:
            out = t.shape.outline()
            patch = Polygon(out, closed=True, lw=1, ec=REGION, fc=REGION, zorder=1)
            top = (out[:, 0].min() + out[:, 0].max()) / 2, out[:, 1].max()
            label = ax.text(*top, f"n={t.frame}", color=REGION, fontsize=7, ha="center",
                            va="bottom")
            self.patches.append((t, ax.add_patch(patch), label))
        if self.coms:
            path = np.array([t.position_target[:2] for t in self.coms])
            ax.plot(path[:, 0], path[:, 1], "--", color=COM, lw=0.8, alpha=0.6, zorder=2)
            self.com_marks = ax.scatter(path[:, 0], path[:, 1], marker="x", c=COM, s=40,
                                        zorder=3)
        self.com_line = ax.plot([], [], "-", color=COM, lw=1.0, alpha=0.5, zorder=2)[0]
        self.com_dot = ax.plot([], [], "P", color=COM, ms=8, mec="white", mew=0.8,
                               zorder=6)[0]
        self.state_marks = [ax.scatter(*t.position_target[:, :2].T, s=60, facecolors="none",
                                       edgecolors=PARTICLE, zorder=4) for t in self.states]
        self.trails = ax.add_collection(LineCollection([], lw=0.8, zorder=2))
        self.dots = ax.scatter(*self.xy[0, ~self.hl].T, s=12, c=AGENT, zorder=5, lw=0)
        self.hdots = ax.scatter(*self.xy[0, self.hl].T, s=45, c=HIGHLIGHT, ec="black",
                                lw=0.6, zorder=7)

    def title(self, n: int, full: bool = True) -> str:
        return frame_title(self.name, n, self.traj, full)

    def draw(self, n: int, full_title: bool = True):
        """Move every artist to frame ``n``."""
        for t, patch, label in self.patches:
            near = abs(n - t.frame) <= NEAR
            patch.set(lw=2.2 if near else 0.8, fc=(*_rgb(REGION), 0.2 if near else 0.0),
                      ec=(*_rgb(REGION), 1.0 if near else 0.35))
            label.set(alpha=1.0 if near else 0.4, fontweight="bold" if near else "normal")
        if self.coms:
            self.com_marks.set_sizes([110 if abs(n - t.frame) <= NEAR else 40 for t in self.coms])
        self.com_dot.set_data([self.com[n, 0]], [self.com[n, 1]])
        self.com_line.set_data(self.com[:n + 1, 0], self.com[:n + 1, 1])
        for t, mark in zip(self.states, self.state_marks):
            near = abs(n - t.frame) <= NEAR
            mark.set(linewidths=2.0 if near else 0.8, alpha=1.0 if near else 0.45)
        self._draw_trails(n)
        self.dots.set_offsets(self.xy[n, ~self.hl])
        self.hdots.set_offsets(self.xy[n, self.hl])
        self.ax.set_title(self.title(n, full_title), fontsize=9 if full_title else 8)

    def _draw_trails(self, n: int):
        seg = self.xy[max(n - TRAIL, 0):n + 1]
        if len(seg) < 2:
            self.trails.set_segments([])
            return
        segs = np.stack([seg[:-1], seg[1:]], axis=2)  # (k, agents, 2, 2)
        k, agents = segs.shape[:2]
        age = np.repeat(np.arange(1, k + 1) / k, agents)
        self.trails.set_segments(segs.reshape(-1, 2, 2))
        self.trails.set_color(np.c_[np.tile(self.trail_rgb, (k, 1)), 0.5 * age])


def _legend(fig, scene: _Scene):
    """One figure legend below the axes, listing only what the scene draws."""
    h = [plt.Line2D([], [], ls="", marker="o", ms=4, color=AGENT, label="agents")]
    if scene.hl.any():
        h.append(plt.Line2D([], [], ls="", marker="o", ms=7, color=HIGHLIGHT, mec="black",
                            label="highlighted"))
    h.append(plt.Line2D([], [], marker="P", ms=7, color=COM, mec="white", label="centre of mass"))
    if scene.coms:
        h.append(plt.Line2D([], [], ls="--", marker="x", color=COM, lw=0.8, label="COM target"))
    if scene.states:
        h.append(plt.Line2D([], [], ls="", marker="o", mfc="none", ms=7, color=PARTICLE,
                            label="agent target"))
    if scene.regions:
        h.append(Polygon([[0, 0]], fc=(*_rgb(REGION), 0.2), ec=REGION, label="region"))
    fig.legend(handles=h, loc="lower center", ncol=min(len(h), 6), fontsize=7, frameon=False)


def _figsize(scene: _Scene, width: float) -> tuple[float, float]:
    (x0, x1), (y0, y1) = scene.ax.get_xlim(), scene.ax.get_ylim()
    ratio = np.clip((y1 - y0) / (x1 - x0), 0.4, 2.5)
    return width, width * ratio + 0.6


def animate(problem, trajectory, path, *, fps: int | None = None,
            max_frames: int | None = None, title=None) -> Path:
    """Write an animated GIF of ``trajectory`` seen from above; returns the path.

    Long trajectories are subsampled to about ``max_frames + 1`` frames (default 150, at
    ``fps`` 20), keeping every keyframe and the last frame.  ``title`` overrides the problem
    name in the title.  A cloth goes to :func:`.render_cloth.animate` and a blend of source
    clips to :func:`.render_blend.animate` (their own defaults).
    """
    module = _renderer_3d(problem)
    if module is not None:
        given = {k: v for k, v in (("fps", fps), ("max_frames", max_frames)) if v is not None}
        return module.animate(problem, trajectory, path, title=title, **given)
    fps, max_frames = fps or 20, 150 if max_frames is None else max_frames
    path = Path(path)
    fig, ax = plt.subplots()
    try:
        scene = _Scene(ax, problem, trajectory, name=title)
        fig.set_size_inches(*_figsize(scene, 6.0))
        _legend(fig, scene)
        fig.tight_layout(rect=(0, 0.05, 1, 1))
        frames = select_frames(trajectory.steps, keyframes(problem), max_frames)
        write_gif(fig, scene.draw, frames, path, fps)
    finally:
        plt.close(fig)
    return path


def snapshot(problem, trajectory, path, frames=None) -> Path:
    """Write a PNG of small multiples: by default the first frame, each keyframe and the last.

    At most 6 panels: longer lists keep their first and last frame and are thinned evenly.
    A cloth goes to :func:`.render_cloth.snapshot`, a blend of source clips to
    :func:`.render_blend.snapshot`.
    """
    module = _renderer_3d(problem)
    if module is not None:
        return module.snapshot(problem, trajectory, path, frames)
    path = Path(path)
    frames = snapshot_frames(problem, trajectory, frames)
    cols = {1: 1, 2: 2, 3: 3, 4: 2}.get(len(frames), 3)
    rows = -(-len(frames) // cols)
    fig, axes = plt.subplots(rows, cols, squeeze=False)
    try:
        scenes = [_Scene(ax, problem, trajectory) for ax in axes.flat[:len(frames)]]
        for ax in axes.flat[len(frames):]:
            ax.set_visible(False)
        w, h = _figsize(scenes[0], 3.6)
        fig.set_size_inches(w * cols, (h - 0.2) * rows + 0.5)
        for scene, n in zip(scenes, frames):
            scene.draw(n, full_title=False)
        fig.suptitle(problem.name, fontsize=11)
        _legend(fig, scenes[0])
        fig.tight_layout(rect=(0, 0.04, 1, 1))
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path


def _series(history, key):
    vals = np.array([np.nan if h.get(key) is None else float(h[key]) for h in history])
    return np.where(vals > 0, vals, np.nan)  # log scale: hide non-positive values


def convergence(result, path) -> Path:
    """Write a PNG of objective and keyframe error versus iteration and versus seconds."""
    path = Path(path)
    history = list(getattr(result, "history", None) or [])
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    try:
        fig.suptitle(f"{getattr(result, 'method', '?')} / gradient: "
                     f"{getattr(result, 'gradient', '?')}", fontsize=11)
        if not history:
            for ax in axes:
                ax.text(0.5, 0.5, "no iterations recorded", ha="center", va="center",
                        transform=ax.transAxes, color="gray")
                ax.set_xticks([]), ax.set_yticks([])
        else:
            start = getattr(result, "start", None) or {}
            if start.get("objective") is not None and np.isfinite(start["objective"]):
                history = [{"iteration": 0, "seconds": 0.0, **start}] + history
            for ax, xkey, xlabel in ((axes[0], "iteration", "iteration (0: the start)"),
                                     (axes[1], "seconds", "wall time [s]")):
                x = [h.get(xkey, i + 1) for i, h in enumerate(history)]
                style = ".-" if len(history) < 30 else "-"
                ax.plot(x, _series(history, "objective"), style, color=AGENT, label="objective")
                ax.plot(x, _series(history, "keyframe_error"), style, color=PARTICLE,
                        label="keyframe error")
                ax.set_yscale("log")
                ax.set_xlabel(xlabel)
                ax.grid(alpha=0.3, which="both", lw=0.5)
            axes[0].legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path
