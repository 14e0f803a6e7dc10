"""Fig. 6 side by side: the fall clip, the optimised blend and the walk clip, in 3-D.

For a problem with a :class:`..views.BlendView` (``problems/cape_blend.py``): ``animate`` writes
a GIF and ``snapshot`` a PNG with three panels per time, left the fall source clip, middle
the blend, right the walk source clip, each with its cape and its character's capsules.
Blend frame ``k`` goes with each clip's frame at its start time plus ``k dt``
(:func:`clip_frame`).  The animation opens with a lead-in of :data:`LEAD_IN` s in which the
middle panel shows the fall clip itself; from ``k = 0`` the blend's cape is orange
(:data:`BLEND`) and the walk target, the problem's keyframe, a red wireframe.  Every panel
keeps one scale over all its frames (equal aspect, equal lengths across panels).
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from ..views import BlendView, view_of
from .cloth import CLOTH, Box, ClothPanel, legend, same_scale, save_grid, targets
from .flock import HIGHLIGHT
from .frames import keyframes, mass_centers, select_frames, write_gif
from .verdicts import say_checks, titled

BLEND = HIGHLIGHT  # orange, as highlighted agents in the flock figures
LEAD_IN = 0.3  # s of the fall shown before the blend starts
PANELS = {"fall": "fall (source clip)", "blend": "blend (optimised)",
          "walk": "walk (source clip)"}


class Shown(NamedTuple):
    """What one panel draws at one time: the cape ``x`` of ``model`` at its time ``t``
    (for its colliders and the title), in ``color``."""

    model: object
    x: np.ndarray
    t: float
    color: str


def clip_frame(problem, kind: str, k: int) -> int:
    """The frame of source clip ``kind`` ("fall" or "walk") that goes with blend frame ``k``:
    ``t_a / dt + k`` or ``t_b / dt + k``."""
    return view_of(problem, BlendView).clip_frame(kind, k, problem.dt)


def lead_in(problem, seconds: float = LEAD_IN) -> int:
    """Frames shown before the blend: ``seconds`` worth, fewer if either clip starts sooner."""
    return max(0, min(int(round(seconds / problem.dt)), clip_frame(problem, "fall", 0),
                      clip_frame(problem, "walk", 0)))


def shown(problem, trajectory, panel: str, k: int) -> Shown:
    """What ``panel`` ("fall", "blend" or "walk") draws at blend frame ``k``: the source
    clip's matching frame, or the blend's frame k (before the blend, k < 0: the fall clip)."""
    if panel == "blend" and k >= 0:
        return Shown(problem.model, np.asarray(trajectory.x[k]), k * trajectory.dt, BLEND)
    kind = "fall" if panel == "blend" else panel
    clip = view_of(problem, BlendView).clip(kind)
    n, traj = clip_frame(problem, kind, k), clip.trajectory
    if not 0 <= n <= traj.steps:
        raise ValueError(f"blend frame {k} needs {kind} clip frame {n}, outside 0..{traj.steps}")
    return Shown(clip.model, np.asarray(traj.x[n]), n * traj.dt, CLOTH)


def panel_box(problem, trajectory, panel: str, ks) -> Box:
    """Limits holding the panel's capes and capsules at every blend frame in ``ks`` (and
    the keyframe target in the blend panel)."""
    frames = [shown(problem, trajectory, panel, k) for k in ks]
    points = [s.x for s in frames]
    if panel == "blend":
        points += [m.points for m in targets(problem)]
    bodies = [[b.shape(s.t) for b in s.model.colliders] for s in frames]
    return Box(points, bodies)


class BlendPanel(ClothPanel):
    """One of the three panels ("fall", "blend" or "walk") over blend frames ``ks``;
    ``draw(k)`` shows blend frame k, each frame with its own model (the blend panel's
    lead-in is the fall clip's)."""

    def __init__(self, ax, problem, trajectory, panel: str, ks, box: Box):
        xs = np.array([shown(problem, trajectory, panel, k).x for k in ks])
        super().__init__(ax, problem.model, box, view_of(problem, BlendView),
                         path=mass_centers(problem.model.masses, xs),
                         terms=targets(problem) if panel == "blend" else ())
        self.problem, self.trajectory, self.panel = problem, trajectory, panel
        self.markers = problem.objective_terms.markers() if panel == "blend" else []
        self.name = PANELS[panel]
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MaxNLocator(4))

    def draw(self, k: int, full_title: bool = True, *, hold: bool = False):
        """Show blend frame ``k``; the blend panel says how each keyframe at ``k`` went (with
        ``hold``, at the latest keyframe frame up to ``k``)."""
        s = shown(self.problem, self.trajectory, self.panel, k)
        self.show(s.model, s.x, s.t, s.color)
        if k >= 0:
            self.show_targets(k)
        self.dynamic += say_checks(self.ax, self.markers, self.trajectory, k, metres=True,
                                   hold=hold, large=full_title)
        self.set_title(self.title(k, s.t, full_title), full_title)

    def title(self, k: int, t: float, full: bool = True) -> str:
        """The panel's name and its clip's time (the blend's own clock in the middle)."""
        clock = f"t = {t:.2f} s"
        if self.panel == "blend":
            clock = (f"{clock} of {self.problem.steps * self.problem.dt:.2f} s" if k >= 0
                     else f"lead-in: fall clip at {clock}")
        return f"{self.name}\n{clock}" if full else f"{self.panel}  {clock}"


def _handles():
    return [Patch(fc=BLEND, label=PANELS["blend"])]


def blend_frames(problem) -> np.ndarray:
    """The blend frames an animation may show: the lead-in (negative) and ``0..steps``."""
    return np.arange(-lead_in(problem), problem.steps + 1)


def side_by_side(fig, problem, trajectory, ks) -> list[BlendPanel]:
    """The fall, blend and walk panels side by side in ``fig``, over blend frames ``ks``."""
    boxes = same_scale([panel_box(problem, trajectory, p, ks) for p in PANELS])
    return [BlendPanel(fig.add_subplot(1, 3, i + 1, projection="3d"), problem, trajectory, p, ks,
                       box) for i, (p, box) in enumerate(zip(PANELS, boxes))]


def animate(problem, trajectory, path, *, fps: int = 15, max_frames: int = 80,
            title=None) -> Path:
    """Write the three-panel GIF; about ``max_frames + 1`` frames, always with the blend's
    first and last; ``title`` overrides the problem name.  Returns the path."""
    path, ks = Path(path), blend_frames(problem)
    name = problem.name if title is None else title
    fig = plt.figure(figsize=(16.0, 6.4))
    try:
        panels = side_by_side(fig, problem, trajectory, ks)
        legend(fig, panels[1], _handles())
        fig.subplots_adjust(left=0, right=1, bottom=0.08, top=0.85, wspace=0.02)

        def draw(i):
            k = int(ks[i])
            for panel in panels:
                panel.draw(k, hold=True)
            stage = (f"blend frame {k} / {problem.steps}" if k >= 0
                     else f"lead-in, {-k * problem.dt:.2f} s before the blend")
            fig.suptitle(f"{name} \u2014 {stage}", fontsize=11, y=0.985)

        frames = select_frames(len(ks) - 1, [-ks[0]], max_frames)  # keep the blend's start
        write_gif(fig, draw, frames, path, fps)
    finally:
        plt.close(fig)
    return path


def snapshot(problem, trajectory, path, frames=None) -> Path:
    """Write a PNG: a row per panel (fall, blend, walk), a column per blend frame
    (default: the start, two between and the end of the blend, and every keyframe, where
    the blend panel says whether it was hit)."""
    path, steps = Path(path), problem.steps
    ks = sorted({int(k) for k in ([*np.round(np.linspace(0, steps, 4)), *keyframes(problem)]
                                 if frames is None else frames)})
    if not ks or ks[0] < 0 or ks[-1] > steps:
        raise ValueError(f"snapshot frames must be in 0..{steps}, got {ks}")
    rows, cols, middle = len(PANELS), len(ks), None
    fig = plt.figure(figsize=(3.2 * cols, 3.0 * rows + 0.7))
    try:
        boxes = same_scale([panel_box(problem, trajectory, p, range(steps + 1)) for p in PANELS])
        for r, (p, box) in enumerate(zip(PANELS, boxes)):
            for c, k in enumerate(ks):
                ax = fig.add_subplot(rows, cols, r * cols + c + 1, projection="3d")
                panel = BlendPanel(ax, problem, trajectory, p, range(steps + 1), box)
                panel.draw(k, full_title=False)
                middle = panel if p == "blend" else middle
        save_grid(fig, path, titled(problem.name, middle.markers, trajectory, problem), middle,
                  _handles())
    finally:
        plt.close(fig)
    return path
