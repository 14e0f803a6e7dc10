"""What a cloth picture shows of its keyframe targets, so that a viewer can tell whether each
was hit: a camera that sees a target's extent (a flat target seen edge-on is a solid band
that hides the cloth), and the cloth's distance to its target, per particle, as colour in
millimetres on a scale fixed per problem around the keyframes' tolerance
(:class:`DistanceScale`), with a colour bar.

Plotting-light: the camera choice and the distances are numpy only; :func:`colorbar` and
:func:`distance_colors` use matplotlib's colour maps.
"""
from __future__ import annotations

from dataclasses import dataclass

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.colors import Normalize

from .verdicts import format_mm

DISTANCE_MAP = "viridis"  # dark: on the target; yellow: far from it
ELEVATIONS = np.arange(5.0, 80.0, 5.0)
AZIMUTHS = np.arange(-180.0, 180.0, 5.0)
TOLERANCES_SHOWN = 3  # the colour bar of the distance spans 0 to this many tolerances
UNJUDGED_SPAN = 0.05  # of the targets' extent: the bar's span where no tolerance is checked


def camera_direction(camera) -> np.ndarray:
    """The unit vector from the scene towards a camera at ``(elevation, azimuth)`` degrees."""
    el, az = np.radians(camera)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def extent_seen(points, camera) -> float:
    """How much of the spread of ``points`` ``(k, 3)`` a camera at ``camera`` sees, from 0
    (a flat target seen edge-on, or a line end-on) to 1 (seen square-on): the area of the
    points' covariance ellipse projected onto the image plane over its largest projection
    (``e^T adj(C) e`` over the largest eigenvalue of ``adj(C)``)."""
    return float(_seen(points, camera_direction(camera)[None])[0])


def _seen(points, directions) -> np.ndarray:
    """:func:`extent_seen` of ``points`` from each of the unit ``directions`` ``(m, 3)``."""
    p = np.asarray(points, float).reshape(-1, 3)
    if len(p) < 3:
        return np.ones(len(directions))  # a point or two: any side shows them
    w, vectors = np.linalg.eigh(np.cov(p.T))
    w, vectors = w[::-1].clip(min=0), vectors[:, ::-1]  # largest, middle, smallest spread
    if w[1] <= 1e-12 * max(w[0], 1e-300):
        return np.ones(len(directions))  # (nearly) on a line: a line from almost everywhere
    adj = np.array([w[1] * w[2], w[0] * w[2], w[0] * w[1]])  # adj(C)'s eigenvalues
    return (directions @ vectors) ** 2 @ adj / adj.max()


def target_camera(points_list, default) -> tuple[float, float]:
    """The camera nearest ``default`` (elevation, azimuth) that sees every target of
    ``points_list`` well: the worst :func:`extent_seen` over the targets is kept within 90 %
    of the best any camera above the ground reaches (and at least 0.5, a target 45 degrees
    from edge-on, where that is possible); ``default`` itself when it qualifies."""
    targets = [np.asarray(p, float).reshape(-1, 3) for p in points_list]
    if not targets:
        return tuple(default)
    cameras = [(el, az) for el in ELEVATIONS for az in AZIMUTHS]
    directions = np.array([camera_direction(c) for c in cameras])
    seen = np.min([_seen(t, directions) for t in targets], axis=0)
    need = min(0.5, 0.9 * seen.max())
    if min(extent_seen(t, default) for t in targets) >= need:
        return tuple(default)
    away = np.arccos(np.clip(directions @ camera_direction(default), -1.0, 1.0))
    best = np.flatnonzero(seen >= need)
    return cameras[best[np.argmin(away[best])]]


def distances(marker, x) -> np.ndarray | None:
    """Each targeted particle's distance to its target in metres (:meth:`..objectives.markers.
    Marker.targeted`: a whole shape's every particle, else those it names), or None for a marker
    that targets no particle positions (a centre of mass)."""
    targeted = marker.targeted(np.asarray(x, float))
    return None if targeted is None else np.linalg.norm(targeted - marker.points, axis=1)


@dataclass(frozen=True)
class DistanceScale:
    """The colour scale of each particle's distance to its target, in mm, fixed per problem:
    0 to ``top``, with ``tolerance`` (the tightest position tolerance, if any) marked;
    farther distances take the top colour (clipped)."""

    top: float
    tolerance: float | None

    @property
    def norm(self) -> Normalize:
        return Normalize(vmin=0.0, vmax=self.top, clip=True)


def distance_scale(markers) -> DistanceScale:
    """The :class:`DistanceScale` of a problem's keyframe ``markers``: up to
    :data:`TOLERANCES_SHOWN` times the tightest position tolerance of those coloured by
    distance (targets for particles), or, where none has a tolerance, :data:`UNJUDGED_SPAN`
    of their targets' extent.  It depends on the problem alone, so every picture of one
    problem (any trajectory, any frame) shares it."""
    coloured = [m for m in markers if m.kind.particles]
    tolerances = [t for m in coloured if (t := m.position_tolerance) is not None]
    if tolerances:
        tolerance = 1e3 * min(tolerances)
        return DistanceScale(TOLERANCES_SHOWN * tolerance, tolerance)
    extent = max([float(np.ptp(m.points, axis=0).max()) for m in coloured] + [0.0])
    return DistanceScale(1e3 * UNJUDGED_SPAN * extent if extent > 0 else 100.0, None)


def distance_colors(millimetres, scale: DistanceScale) -> np.ndarray:
    """RGB of each distance in mm on :data:`DISTANCE_MAP` (beyond ``scale.top``: the top
    colour)."""
    return matplotlib.colormaps[DISTANCE_MAP](scale.norm(np.asarray(millimetres, float)))[..., :3]


def colorbar(fig, scale: DistanceScale, rect=(0.3, 0.035, 0.4, 0.018)):
    """A horizontal colour bar of the distance in mm in figure coordinates ``rect``, the
    tolerance marked on it, saying that farther distances are clipped to its top colour."""
    mappable = matplotlib.cm.ScalarMappable(norm=scale.norm, cmap=DISTANCE_MAP)
    bar = fig.colorbar(mappable, cax=fig.add_axes(rect), orientation="horizontal",
                       extend="max")
    top = format_mm(scale.top)
    said = ("no tolerance checked" if scale.tolerance is None
            else f"the line at {scale.tolerance:.3g}: tolerance {format_mm(scale.tolerance)}")
    bar.set_label(f"each particle's distance to its keyframe target [mm]\n{said}; "
                  f"beyond {top}: clipped (top colour)", fontsize=7)
    if scale.tolerance is not None:
        bar.ax.axvline(scale.tolerance, color="white", lw=2.5)
        bar.ax.axvline(scale.tolerance, color="black", lw=1.0)
        bar.set_ticks(scale.tolerance * np.arange(TOLERANCES_SHOWN + 1))
    bar.ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:.3g}"))
    bar.ax.tick_params(labelsize=6)
    return bar
