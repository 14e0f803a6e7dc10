"""What a cloth picture shows of its keyframe targets, so that a viewer can tell whether each
was hit: a camera that sees a target's extent (a flat target seen edge-on is a solid band
that hides the cloth), and the cloth's distance to its target, per particle, as colour in
millimetres with a colour bar.

Plotting-light: the camera choice and the distances are numpy only; :func:`colorbar` and
:func:`distance_colors` use matplotlib's colour maps.
"""
from __future__ import annotations

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.colors import LogNorm

DISTANCE_MAP = "viridis"  # dark: on the target; yellow: far from it
ELEVATIONS = np.arange(5.0, 80.0, 5.0)
AZIMUTHS = np.arange(-180.0, 180.0, 5.0)


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
    """Each targeted particle's distance to its target in metres (a "shape" marker: every
    particle; "particles": those it names), or None for a marker that targets no particle
    positions (a centre of mass)."""
    x = np.asarray(x, float)
    if marker.kind == "shape":
        return np.linalg.norm(x - marker.points, axis=1)
    if marker.kind == "particles":
        return np.linalg.norm(x[marker.particles] - marker.points, axis=1)
    return None


def center_distance(marker, x, masses) -> float:
    """The distance in metres of the centre of mass of positions ``x`` (weighted by
    ``masses``) to a "center" marker's target."""
    w = np.asarray(masses, float)
    return float(np.linalg.norm(w @ np.asarray(x, float) / w.sum() - marker.points[0]))


def distance_norm(millimetres) -> LogNorm:
    """A log colour scale in mm from 1 mm to the largest of ``millimetres`` rounded up to 1,
    2 or 5 times a power of ten (at least 10 mm): a hit within a millimetre and a miss of a
    metre both read off one bar."""
    values = np.asarray([v for v in np.ravel(millimetres) if np.isfinite(v)] or [1.0])
    decade = 10 ** np.floor(np.log10(max(values.max(), 1.0)))
    top = decade * next(k for k in (1, 2, 5, 10) if k * decade >= values.max())
    return LogNorm(vmin=1.0, vmax=max(10.0, top), clip=True)


def distance_colors(millimetres, norm: LogNorm) -> np.ndarray:
    """RGB of each distance in mm on :data:`DISTANCE_MAP` (below 1 mm: the bottom colour)."""
    values = np.maximum(np.asarray(millimetres, float), norm.vmin)
    return matplotlib.colormaps[DISTANCE_MAP](norm(values))[..., :3]


def colorbar(fig, norm: LogNorm, rect=(0.3, 0.035, 0.4, 0.018)):
    """A horizontal colour bar of the distance in mm, in figure coordinates ``rect``."""
    mappable = matplotlib.cm.ScalarMappable(norm=norm, cmap=DISTANCE_MAP)
    bar = fig.colorbar(mappable, cax=fig.add_axes(rect), orientation="horizontal")
    bar.set_label("distance of each particle to its keyframe target [mm] (at keyframe "
                  "frames)", fontsize=7)
    bar.ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    bar.ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    bar.ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    bar.ax.tick_params(labelsize=6)
    return bar


def miss_text(millimetres) -> str:
    """``"rms 2.2 mm, max 5.8 mm"`` of distances in mm."""
    d = np.asarray(millimetres, float)
    return f"rms {format_mm(np.sqrt(np.mean(d ** 2)))}, max {format_mm(d.max())}"


def format_mm(value: float) -> str:
    """A distance in mm to two significant figures (``"< 0.01 mm"`` below that)."""
    if value < 0.01:
        return "< 0.01 mm"
    return f"{value:.2g} mm" if value < 10 else f"{value:.0f} mm"
