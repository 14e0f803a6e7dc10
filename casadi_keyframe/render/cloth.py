"""A cloth in 3-D: a GIF (``animate``) or small multiples at the keyframes (``snapshot``).

The cloth is a Lambert-shaded triangle surface, its side turned away from the camera tinted
(a cape's inside and outside differ), drawn in one collection with the round colliders'
shaded surfaces, so that matplotlib's per-polygon depth sort (the painter's algorithm)
hides what is behind across cloth and bodies; planes lie beneath, translucent; pinned and
attached particles are dark dots, keyframe targets red (a wireframe for a whole-cloth
target), the centre-of-mass path a thin line and the view's ring a thick circle, drawn over
the surfaces.  Axis limits (equal aspect, :class:`Box`) and the view's camera
(:class:`..views.ClothView`) are fixed for a whole animation.  :class:`ClothPanel` draws the
cloth at given positions, so that a picture of something other than one trajectory (the
blend's panels, :mod:`.blend`) draws alike; :class:`TrajectoryPanel` draws a cloth problem's
trajectory frame by frame.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Patch
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..geometry import circle
from ..objectives.markers import Points, WholeShape
from ..views import ClothView, view_of
from .frames import (frame_title, grid_shape, keyframes, mass_centers, save_figure,
                     select_frames, snapshot_frames, write_gif)
from .targets import (camera_direction, colorbar, distance_colors, distance_scale, distances,
                      target_camera)
from .verdicts import say_checks, titled

CLOTH, TARGET, BODY, MARK, RING, COM = "#6a8fc7", "#d62728", "0.5", "0.1", "#e1812c", "#7b4ea3"
BACK = "#c9b58f"  # the side of a cloth turned away from the camera (a cape's inside)
BODY_RGB = "0.72"  # colliders' shaded surfaces
LIGHT = np.array([0.5, -0.6, 0.65]) / np.linalg.norm([0.5, -0.6, 0.65])  # the camera's side


def face_colors(vertices, faces, color=CLOTH, light=LIGHT, *, back=None, eye=None) -> np.ndarray:
    """RGBA per polygon ``vertices[faces]``: ``color`` times ``0.3 + 0.7 |cos|`` of its
    normal to ``light``.

    Both sides are lit alike; with ``back`` and ``eye`` (the direction to the camera), a
    polygon whose normal turns away from the camera is ``back`` instead, so the two sides
    of a cloth (a cape's inside and outside) differ.  A degenerate polygon gets the ambient
    part only.
    """
    return shade(np.asarray(vertices, dtype=float)[np.asarray(faces)], color, light,
                 back=back, eye=eye)


def shade(polygons, color, light=LIGHT, *, back=None, eye=None) -> np.ndarray:
    """RGBA per polygon of ``polygons`` ``(m, k, 3)`` (see :func:`face_colors`)."""
    p = np.asarray(polygons, dtype=float)
    if p.shape[1] == 3:
        normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    else:  # a quad's normal: the cross product of its diagonals
        normal = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    length = np.linalg.norm(normal, axis=1)
    cos = np.abs(normal @ np.asarray(light, float)) / np.where(length > 0, length, 1.0)
    lit = 0.3 + 0.7 * np.clip(np.nan_to_num(cos), 0.0, 1.0)
    rgb = np.tile(matplotlib.colors.to_rgb(color), (len(p), 1))
    if back is not None and eye is not None:
        rgb[facing_away(p, eye)] = matplotlib.colors.to_rgb(back)
    return np.c_[lit[:, None] * rgb, np.ones(len(p))]


def back_color(color):
    """The colour of a cloth's back side: :data:`BACK` for the default cloth colour, else
    ``color`` halfway to white (the blend's orange cape gets a pale orange inside)."""
    if color == CLOTH:
        return BACK
    return tuple(0.5 + 0.5 * np.asarray(matplotlib.colors.to_rgb(color)))


def facing_away(polygons, eye) -> np.ndarray:
    """Whether each polygon's normal (by its winding) turns away from the camera at ``eye``."""
    p = np.asarray(polygons, dtype=float)
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) @ np.asarray(eye, float) < 0


def _extent(points) -> tuple[np.ndarray, np.ndarray]:
    return np.min([p.min(0) for p in points], 0), np.max([p.max(0) for p in points], 0)


class Box:
    """Fixed limits holding ``points`` (a list of ``(k, 3)`` arrays) and ``bodies`` (per
    frame, a list of body shapes, :class:`~..geometry.BodyShape`); shapes that lie beneath
    (planes) are sized to the rest."""

    def __init__(self, points, bodies):
        pts = list(points)
        shapes = [shape for frame in bodies for shape in frame]
        pts += [shape.extent(None) for shape in shapes if not shape.beneath]
        lo, hi = _extent(pts)
        self.mid, self.half = (lo + hi) / 2, 0.6 * max((hi - lo).max(), 1e-3)
        pts += [shape.polygons(self.mid, self.half)[0] for shape in shapes if shape.beneath]
        lo, hi = _extent(pts)
        span = max((hi - lo).max(), 1e-3)
        half = np.maximum(hi - lo, 0.3 * span) / 2 + 0.03 * span
        self.lo, self.hi = (lo + hi) / 2 - half, (lo + hi) / 2 + half

    @classmethod
    def of(cls, problem, trajectory, *more) -> "Box":
        """The box over all frames of a cloth problem's ``trajectory`` (and of ``more``
        trajectories of it), its targets, its ring and its colliders."""
        pts = [np.asarray(t.x).reshape(-1, 3) for t in (trajectory, *more)]
        pts += [m.points[:, :3] for m in targets(problem)]
        ring = view_of(problem, ClothView).ring
        if ring:
            pts.append(circle(ring.center, ring.normal, ring.radius))
        bodies = [[b.shape(n * trajectory.dt) for b in problem.model.colliders]
                  for n in range(trajectory.steps + 1)]
        return cls(pts, bodies)


def same_scale(boxes: list) -> list:
    """Give every box the largest half-extent of any, per axis, about its own centre, so
    panels side by side show lengths alike (the blend's three clips)."""
    half = np.max([(b.hi - b.lo) / 2 for b in boxes], 0)
    for b in boxes:
        mid = (b.lo + b.hi) / 2
        b.lo, b.hi = mid - half, mid + half
    return boxes


def targets(problem) -> list:
    """The markers of the problem's keyframes that a cloth picture draws (by their figure,
    :data:`ClothPanel.FIGURES`: a region's outline, 2-D, is not drawn in 3-D, nor a
    keyframe on velocities only)."""
    return [m for m in problem.objective_terms.markers()
            if m.kind.figure in ClothPanel.FIGURES]


class ClothPanel:
    """One 3-D axes over fixed limits ``box`` seen from ``camera`` (default: ``view``'s),
    with a centre-of-mass ``path`` and the view's ring drawn once; :meth:`show` draws one
    frame's cloth and colliders, :meth:`show_targets` the keyframe markers of ``terms`` at
    a frame (or, faded and labelled, those due next)."""

    def __init__(self, ax, model, box: Box, view: ClothView, *, path=None, terms=(),
                 camera=None):
        self.ax, self.model, self.box, self.ring = ax, model, box, view.ring
        self.terms = list(terms)
        self.dynamic = []
        self.camera = tuple(view.camera if camera is None else camera)
        ax.set(xlim=(box.lo[0], box.hi[0]), ylim=(box.lo[1], box.hi[1]),
               zlim=(box.lo[2], box.hi[2]))
        ax.set_box_aspect(box.hi - box.lo)
        ax.view_init(*self.camera)
        ax.computed_zorder = False  # planes, then the depth-sorted surfaces, then marks
        self.eye = camera_direction(self.camera)
        ax.tick_params(labelsize=6, pad=0)
        if path is not None:
            ax.plot(*np.asarray(path).T, color=COM, lw=0.8, alpha=0.8)
        if self.ring:
            ax.plot(*circle(self.ring.center, self.ring.normal, self.ring.radius).T, color=RING,
                    lw=3)

    @property
    def marked(self) -> np.ndarray:
        """The model's pinned and attached particles, drawn as dots."""
        return self.model.prescribed_particles()

    def show(self, model, x, t: float, color=CLOTH, *, vertex_rgb=None):
        """Replace the frame's artists with ``model``'s cloth at positions ``x`` shaded
        ``color`` (or, given ``vertex_rgb`` ``(n, 3)``, each face the mean of its vertices'
        colours: the distance to a target), its pinned and attached particles, and its
        colliders at time ``t``."""
        for artist in self.dynamic:
            artist.remove()
        self.dynamic, self.model = [], model
        self._bodies = [body.shape(t) for body in model.colliders]
        self._cloth(np.asarray(x), color, vertex_rgb)
        self._colliders(t)

    def set_title(self, text: str, full: bool = True):
        self.ax.set_title(text, fontsize=9 if full else 8)

    def _add(self, collection):
        self.ax.add_collection3d(collection)
        self.dynamic.append(collection)

    def _cloth(self, x, color, vertex_rgb=None):
        """The cloth's triangles and the round colliders' quads in one collection, so that
        matplotlib's per-polygon depth sort hides what is behind across them (the body
        hides the cape behind it); the cloth's two sides are shaded apart, or, coloured by
        ``vertex_rgb``, lit gently so the colour still reads as its value."""
        faces, marked = self.model.faces, self.marked
        polys = list(x[faces])
        self.facing_away = facing_away(x[faces], self.eye)
        if vertex_rgb is None:
            colors = [face_colors(x, faces, color, back=back_color(color), eye=self.eye)]
        else:
            lit = 0.75 + 0.25 * shade(x[faces], "white")[:, :1]
            colors = [np.c_[lit * np.asarray(vertex_rgb)[faces].mean(1), np.ones(len(faces))]]
        for shape in self._bodies:
            if not shape.beneath:
                vertices, faces = shape.polygons(detail=8)
                polys += list(vertices[faces])
                colors.append(shade(vertices[faces], BODY_RGB))
        self.colors = np.vstack(colors)  # the cloth's faces first, then the bodies' quads
        self._add(Poly3DCollection(polys, facecolors=self.colors,
                                   edgecolors=(0, 0, 0, 0.08), lw=0.15, zorder=1))
        if marked.size:
            self.dynamic.append(self.ax.scatter(*x[marked].T, s=10, c=MARK, depthshade=False,
                                                zorder=2))

    def _colliders(self, t: float):
        """The shapes that lie beneath (planes), drawn beneath everything (the camera looks
        down on them)."""
        for shape in self._bodies:
            if shape.beneath:
                vertices, faces = shape.polygons(self.box.mid, self.box.half)
                self._add(Poly3DCollection(list(vertices[faces]),
                                           facecolors=(0.5, 0.5, 0.5, 0.12),
                                           edgecolors=(0.4, 0.4, 0.4, 0.4), zorder=0))

    @staticmethod
    def is_shape(marker) -> bool:
        """Whether ``marker`` targets every particle's position, drawn as a wireframe (other
        targets are crosses)."""
        return marker.kind.figure is WholeShape

    def _wireframe(self, marker, alpha: float):
        # thinner on fine meshes, else the wireframe hides the cloth (26 x 16 cape)
        lw = min(0.4, 120 / len(self.model.faces))
        self._add(Poly3DCollection(marker.points[self.model.faces], facecolors="none",
                                   lw=lw, zorder=2, edgecolors=matplotlib.colors.to_rgba(
                                       TARGET, 0.6 * alpha)))

    def _crosses(self, marker, alpha: float):
        self.dynamic.append(self.ax.scatter(*marker.points.T, marker="x", s=40, c=TARGET,
                                            zorder=3, alpha=alpha, depthshade=False))

    # how each figure of a keyframe marker is drawn (objectives.markers.Figure); others are not drawn
    FIGURES = {WholeShape: _wireframe, Points: _crosses}

    def show_targets(self, n: int, *, ahead: bool = True):
        """Add the targets of the terms at frame ``n``; with ``ahead``, at a frame between
        keyframes those of the next one, faded and labelled "target at frame N"."""
        here = [t for t in self.terms if t.frame == n]
        if not here and ahead:
            later = [t.frame for t in self.terms if t.frame > n]
            if later:
                here = [t for t in self.terms if t.frame == min(later)]
                self.dynamic.append(self.ax.text2D(
                    0.98, 0.96, f"target at frame {here[0].frame}", color=TARGET,
                    fontsize=8, transform=self.ax.transAxes, va="top", ha="right"))
        alpha = 1.0 if here and here[0].frame == n else 0.35
        for marker in here:
            self.FIGURES[marker.kind.figure](self, marker, alpha)


class TrajectoryPanel(ClothPanel):
    """A cloth problem's ``trajectory`` in one 3-D axes; ``draw(n)`` shows frame ``n``, at a
    keyframe frame coloured by each particle's distance to its target on the problem's
    scale (:func:`.targets.distance_scale`) and saying whether each keyframe was hit."""

    def __init__(self, ax, problem, trajectory, *, name=None, box=None, camera=None):
        super().__init__(ax, problem.model, Box.of(problem, trajectory) if box is None else box,
                         view_of(problem, ClothView),
                         path=mass_centers(problem.model.masses, trajectory.x),
                         terms=targets(problem), camera=camera)
        self.trajectory, self.markers = trajectory, problem.objective_terms.markers()
        self.name = problem.name if name is None else name
        self.scale = distance_scale(self.terms)

    def draw(self, n: int, full_title: bool = True, *, ahead: bool = True,
             hold: bool = False):
        """Replace the frame-dependent artists with those of frame ``n`` (targets due later
        drawn faded and labelled only with ``ahead``), saying how each keyframe at ``n``
        went (with ``hold``, at the latest keyframe frame up to ``n``)."""
        x = self.trajectory.x[n]
        here = [m for m in self.terms if m.frame == n]
        shape = next((m for m in here if self.is_shape(m)), None)
        rgb = None if shape is None else distance_colors(1e3 * distances(shape, x), self.scale)
        self.show(self.model, x, n * self.trajectory.dt, vertex_rgb=rgb)
        for m in here:  # the particles a target names, coloured by their distance
            if m.kind.particles and not self.is_shape(m):
                self.dynamic.append(self.ax.scatter(
                    *m.targeted(x).T, s=22, zorder=3, depthshade=False, edgecolors="black",
                    linewidths=0.4, c=distance_colors(1e3 * distances(m, x), self.scale)))
        self.show_targets(n, ahead=ahead)
        self.dynamic += say_checks(self.ax, self.markers, self.trajectory, n, metres=True,
                                   hold=hold, large=full_title)
        self.set_title(frame_title(self.name, n, self.trajectory, full_title), full_title)


def keyframe_camera(problem, frames, *trajectories) -> tuple[float, float]:
    """The camera nearest the problem's own that sees the extent of the targets of the
    keyframes among ``frames`` and of the cloth of each of ``trajectories`` at those
    keyframes (:func:`.targets.target_camera`): a flat target is not seen edge-on, nor a
    cloth hanging far from it."""
    here = [m for m in targets(problem) if m.frame in set(frames)]
    points = [m.points for m in here] + [t.x[m.frame] for m in here if ClothPanel.is_shape(m)
                                         for t in trajectories]
    return target_camera(points, view_of(problem, ClothView).camera)


def legend(fig, panel: ClothPanel, extra=(), *, bottom: float = 0.0):
    """A figure legend listing only what ``panel`` draws (and the ``extra`` handles), its
    lower edge at ``bottom`` (figure fraction)."""
    line = plt.Line2D
    h = [Patch(fc=CLOTH, label="cloth (front)"), Patch(fc=BACK, label="cloth (back)"), *extra,
         line([], [], color=COM, lw=0.8, label="centre of mass")]
    if panel.marked.size:
        h.append(line([], [], ls="", marker="o", ms=3, color=MARK, label="pinned / attached"))
    if any(panel.is_shape(t) for t in panel.terms):
        h.append(line([], [], color=TARGET, lw=0.8, label="keyframe shape (at its frame)"))
    if not all(panel.is_shape(t) for t in panel.terms):
        h.append(line([], [], ls="", marker="x", color=TARGET,
                      label="keyframe target (at its frame)"))
    if panel.model.colliders:
        h.append(Patch(fc=(0.5, 0.5, 0.5, 0.3), ec=BODY, label="colliders"))
    if panel.ring:
        h.append(line([], [], color=RING, lw=3, label="ring"))
    ncol = min(len(h), max(3, int(fig.get_figwidth() / 1.6)))
    fig.legend(handles=h, loc="lower center", ncol=ncol, fontsize=7, frameon=False,
               bbox_to_anchor=(0.5, bottom))


def animate(problem, trajectory, path, *, fps: int = 15, max_frames: int = 80,
            title=None) -> Path:
    """Write an animated 3-D GIF of a cloth ``trajectory``; returns the path.

    About ``max_frames + 1`` frames, always with every keyframe and the last frame;
    ``title`` overrides the problem name in the title.  One camera for the whole animation,
    the one nearest the problem's that sees every target's extent; between keyframes the
    next target is drawn faded and labelled with its frame; at a keyframe the cloth is
    coloured by its distance to the target (the colour bar in mm), and from it until the
    next one the picture says whether that keyframe was hit."""
    path = Path(path)
    fig = plt.figure(figsize=(8.0, 7.6))
    try:
        panel = TrajectoryPanel(fig.add_subplot(projection="3d"), problem, trajectory,
                                name=title,
                                camera=keyframe_camera(problem, keyframes(problem), trajectory))
        legend(fig, panel, bottom=0.11)
        fig.subplots_adjust(left=0, right=1, bottom=0.16, top=0.94)
        if coloured(problem, range(trajectory.steps + 1)):
            colorbar(fig, panel.scale, rect=(0.3, 0.08, 0.4, 0.014))
        frames = select_frames(trajectory.steps, keyframes(problem), max_frames)
        write_gif(fig, lambda n: panel.draw(n, hold=True), frames, path, fps)
    finally:
        plt.close(fig)
    return path


def snapshot(problem, trajectory, path, frames=None) -> Path:
    """Write a PNG of 3-D small multiples: by default the first frame, each keyframe and
    the last.  Each keyframe panel has the camera that sees its target's extent, the cloth
    coloured by its distance to the target and a line per keyframe saying whether it was
    hit; targets appear only at their own frame; the title counts the hits."""
    path = Path(path)
    frames = snapshot_frames(problem, trajectory, frames)
    rows, cols = grid_shape(len(frames))
    fig = plt.figure(figsize=(3.6 * cols, 3.5 * rows + 1.5))
    try:
        box = Box.of(problem, trajectory)
        for i, n in enumerate(frames):
            ax = fig.add_subplot(rows, cols, i + 1, projection="3d")
            panel = TrajectoryPanel(ax, problem, trajectory, box=box,
                                    camera=keyframe_camera(problem, [n], trajectory))
            panel.draw(n, full_title=False, ahead=False)
        save_grid(fig, path, titled(problem.name, panel.markers, trajectory, problem), panel,
                  scale=panel.scale if coloured(problem, frames) else None)
    finally:
        plt.close(fig)
    return path


def side_by_side(problem, rows: dict, path, frames=None) -> Path:
    """Write a PNG with one row of 3-D panels per trajectory of ``rows`` (``{label:
    trajectory}``, e.g. the optimizer's start and its result) at the same frames (default:
    the first, each keyframe and the last), all in one box; each column seen from the
    camera that shows its keyframe's target, the cloth coloured by its distance to the
    target on the problem's scale, each keyframe panel saying whether it was hit."""
    path = Path(path)
    first = next(iter(rows.values()))
    frames = snapshot_frames(problem, first, frames)
    fig = plt.figure(figsize=(3.2 * len(frames), 3.3 * len(rows) + 1.5))
    try:
        box = Box.of(problem, *rows.values())
        for r, (label, trajectory) in enumerate(rows.items()):
            for c, n in enumerate(frames):
                ax = fig.add_subplot(len(rows), len(frames), r * len(frames) + c + 1,
                                     projection="3d")
                panel = TrajectoryPanel(ax, problem, trajectory, box=box,
                                        camera=keyframe_camera(problem, [n], *rows.values()))
                panel.draw(n, full_title=False, ahead=False)
                ax.set_title(f"{label}: " + ax.get_title() if c == 0 else ax.get_title(),
                             fontsize=8)
        title = "  |  ".join(titled(label, panel.markers, t, problem) for label, t in rows.items())
        save_grid(fig, path, f"{problem.name} \u2014 {title}", panel,
                  scale=panel.scale if coloured(problem, frames) else None)
    finally:
        plt.close(fig)
    return path


def coloured(problem, frames) -> bool:
    """Whether a panel at one of ``frames`` is coloured by distance (a keyframe there has
    particle targets): a picture without one has no colour bar."""
    return any(m.frame in frames and m.kind.particles for m in targets(problem))


def save_grid(fig, path, title: str, panel: ClothPanel, extra=(), *, scale=None) -> None:
    """Save a grid of 3-D panels as a PNG: ``title`` on top, the legend of ``panel`` (and
    ``extra`` handles) below, and with ``scale`` the colour bar of the distance to the
    targets under it; narrow margins."""
    fig.suptitle(title, fontsize=11)
    inch = 1 / fig.get_figheight()
    legend(fig, panel, extra, bottom=(0.78 if scale is not None else 0.05) * inch)
    if scale is not None:
        colorbar(fig, scale, rect=(0.3, 0.5 * inch, 0.4, 0.09 * inch))
    fig.subplots_adjust(left=0.02, right=0.98, bottom=(1.15 if scale is not None else 0.45) * inch,
                        top=1 - 0.75 * inch, wspace=0.05, hspace=0.3)
    save_figure(fig, path, dpi=110)
