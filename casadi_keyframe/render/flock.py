"""A flock seen from above (x, y): a GIF (``animate``) or small multiples at the keyframes
(``snapshot``), drawn by :class:`FlockPanel`.

Agents are dots with fading trails, the highlighted ones (:class:`..views.FlockView`) larger
and orange; centre-of-mass targets crosses on a dashed path, the centre of mass a plus with
its path so far, agent targets open circles, regions outlined polygons, each emphasised
within :data:`NEAR` frames of its keyframe.  A panel at a keyframe says whether each of its
keyframes was hit (:mod:`.verdicts`; an animation keeps saying it until the next keyframe).
Only the first two coordinates of a 3-D flock are drawn.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.patches import Polygon

from ..objectives.markers import Outline, Points
from ..views import FlockView, view_of
from .frames import (frame_title, grid_shape, keyframes, mass_centers, save_figure,
                     select_frames, snapshot_frames, write_gif)
from .verdicts import LARGE, SMALL, say_checks, stack_height, titled

AGENT, HIGHLIGHT, REGION, COM, PARTICLE = "#4c72b0", "#e1812c", "#3a923a", "#7b4ea3", "#c03d3e"
TRAIL, NEAR = 10, 3  # trail length and "near the keyframe" window, in frames
_rgb = matplotlib.colors.to_rgb


class FlockPanel:
    """The artists of one top-down view; ``draw(n)`` updates them to frame ``n``."""

    def __init__(self, ax, problem, traj, *, name=None):
        self.ax, self.traj = ax, traj
        self.name = problem.name if name is None else name
        self.xy = np.asarray(traj.x)[:, :, :2]
        self.markers = markers = problem.objective_terms.markers()
        self.verdicts = []
        # by the figure each is drawn as: regions outlined, particles' targets open circles,
        # the other points (centres of mass) crosses on their path
        self.regions = [m for m in markers if m.kind.figure is Outline]
        self.states = [m for m in markers if m.kind.particles]
        self.coms = sorted((m for m in markers if m.kind.figure is Points and not m.kind.particles),
                           key=lambda m: m.frame)
        self.com = mass_centers(problem.model.masses, self.xy)
        self.hl = np.zeros(self.xy.shape[1], bool)
        self.hl[list(view_of(problem, FlockView).highlight)] = True
        self.trail_rgb = np.where(self.hl[:, None], _rgb(HIGHLIGHT), _rgb(AGENT))
        self._limits()
        self._build()

    def _limits(self):
        pts = np.vstack([self.xy.reshape(-1, 2), self.com]
                        + [m.points[:, :2] for m in self.coms + self.states + self.regions])
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
            out = t.points[:, :2]
            patch = Polygon(out, closed=True, lw=1, ec=REGION, fc=REGION, zorder=1)
            top = (out[:, 0].min() + out[:, 0].max()) / 2, out[:, 1].max()
            label = ax.text(*top, f"n={t.frame}", color=REGION, fontsize=7, ha="center",
                            va="bottom")
            self.patches.append((t, ax.add_patch(patch), label))
        if self.coms:
            path = np.array([m.points[0, :2] for m in self.coms])
            ax.plot(path[:, 0], path[:, 1], "--", color=COM, lw=0.8, alpha=0.6, zorder=2)
            self.com_marks = ax.scatter(path[:, 0], path[:, 1], marker="x", c=COM, s=40,
                                        zorder=3)
        self.com_line = ax.plot([], [], "-", color=COM, lw=1.0, alpha=0.5, zorder=2)[0]
        self.com_dot = ax.plot([], [], "P", color=COM, ms=8, mec="white", mew=0.8,
                               zorder=6)[0]
        self.state_marks = [ax.scatter(*m.points[:, :2].T, s=60, facecolors="none",
                                       edgecolors=PARTICLE, zorder=4) for m in self.states]
        self.trails = ax.add_collection(LineCollection([], lw=0.8, zorder=2))
        self.dots = ax.scatter(*self.xy[0, ~self.hl].T, s=12, c=AGENT, zorder=5, lw=0)
        self.hdots = ax.scatter(*self.xy[0, self.hl].T, s=45, c=HIGHLIGHT, ec="black",
                                lw=0.6, zorder=7)

    def title(self, n: int, full: bool = True) -> str:
        return frame_title(self.name, n, self.traj, full)

    def draw(self, n: int, full_title: bool = True, *, hold: bool = False):
        """Move every artist to frame ``n`` and say how each keyframe at ``n`` went (with
        ``hold``, at the latest keyframe frame up to ``n``)."""
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
        for artist in self.verdicts:
            artist.remove()
        self.verdicts = say_checks(self.ax, self.markers, self.traj, n, metres=False, hold=hold,
                                   large=full_title, above=True)
        size = LARGE if full_title else SMALL
        self.pad = 6.0 + (stack_height(self.verdicts, size) + size if self.verdicts else 0.0)
        self.ax.set_title(self.title(n, full_title), fontsize=9 if full_title else 8,
                          pad=self.pad)  # above what the verdicts say

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


def _legend(fig, panel: FlockPanel):
    """One figure legend below the axes, listing only what the panel draws."""
    h = [plt.Line2D([], [], ls="", marker="o", ms=4, color=AGENT, label="agents")]
    if panel.hl.any():
        h.append(plt.Line2D([], [], ls="", marker="o", ms=7, color=HIGHLIGHT, mec="black",
                            label="highlighted"))
    h.append(plt.Line2D([], [], marker="P", ms=7, color=COM, mec="white", label="centre of mass"))
    if panel.coms:
        h.append(plt.Line2D([], [], ls="--", marker="x", color=COM, lw=0.8, label="COM target"))
    if panel.states:
        h.append(plt.Line2D([], [], ls="", marker="o", mfc="none", ms=7, color=PARTICLE,
                            label="agent target"))
    if panel.regions:
        h.append(Polygon([[0, 0]], fc=(*_rgb(REGION), 0.2), ec=REGION, label="region"))
    fig.legend(handles=h, loc="lower center", ncol=min(len(h), 6), fontsize=7, frameon=False)


def _figsize(panel: FlockPanel, width: float) -> tuple[float, float]:
    (x0, x1), (y0, y1) = panel.ax.get_xlim(), panel.ax.get_ylim()
    ratio = np.clip((y1 - y0) / (x1 - x0), 0.4, 2.5)
    return width, width * ratio + 0.6


def animate(problem, trajectory, path, *, fps: int = 20, max_frames: int = 150,
            title=None) -> Path:
    """Write an animated GIF of ``trajectory`` seen from above; returns the path.

    Long trajectories are subsampled to about ``max_frames + 1`` frames, keeping every
    keyframe and the last frame.  ``title`` overrides the problem name in the title.
    """
    path = Path(path)
    fig, ax = plt.subplots()
    try:
        panel = FlockPanel(ax, problem, trajectory, name=title)
        w, h = _figsize(panel, 6.0)
        fig.set_size_inches(w, h)
        pads = {n: (panel.draw(n, hold=True), panel.pad)[1] for n in keyframes(problem)}
        if pads:  # the layout keeps room for the most any keyframe says
            fig.set_size_inches(w, h + max(pads.values()) / 72)
            panel.draw(max(pads, key=pads.get), hold=True)
        _legend(fig, panel)
        fig.tight_layout(rect=(0, 0.05, 1, 1))
        frames = select_frames(trajectory.steps, keyframes(problem), max_frames)
        write_gif(fig, lambda n: panel.draw(n, hold=True), frames, path, fps)
    finally:
        plt.close(fig)
    return path


def snapshot(problem, trajectory, path, frames=None) -> Path:
    """Write a PNG of small multiples: by default the first frame, each keyframe and the
    last, each keyframe's panel saying whether it was hit; the title counts the hits."""
    path = Path(path)
    frames = snapshot_frames(problem, trajectory, frames)
    rows, cols = grid_shape(len(frames))
    fig, axes = plt.subplots(rows, cols, squeeze=False)
    try:
        panels = [FlockPanel(ax, problem, trajectory) for ax in axes.flat[:len(frames)]]
        for ax in axes.flat[len(frames):]:
            ax.set_visible(False)
        w, h = _figsize(panels[0], 3.6)
        fig.set_size_inches(w * cols, (h - 0.2) * rows + 0.5)
        for panel, n in zip(panels, frames):
            panel.draw(n, full_title=False)
        said = sum(max(p.pad for p in panels[r * cols:(r + 1) * cols]) for r in range(rows))
        fig.set_size_inches(w * cols, (h - 0.2) * rows + 0.5 + said / 72)  # room for them
        fig.suptitle(titled(problem.name, panels[0].markers, trajectory), fontsize=11)
        _legend(fig, panels[0])
        fig.tight_layout(rect=(0, 0.04, 1, 1))
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path
