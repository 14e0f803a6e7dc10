"""Planar target shapes for region keyframes: box, disc, any simple polygon.

Each shape writes its signed distance once, symbolically (negative inside, positive
outside); the numeric ``signed_distance`` evaluates that same CasADi expression.  Shapes
live in the ground plane: a point's first two coordinates are used.

The distances are exact (no smoothing offset), so a region term ``max(0, sd + margin)^2``
and its gradient are exact too.  Where a square root meets a zero argument (a disc's
centre, a point on a polygon's edge, any point inside a box) its derivative is 0, not NaN:
see :func:`_norm`.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

_SMALLEST_NORMAL = float(np.finfo(float).tiny)  # 2.2e-308; its square root is 1.5e-154


class Shape:
    """Base class: subclasses define ``sd_expr(p)`` for a 2-vector ``p`` and ``outline()``."""

    def sd_expr(self, p):
        raise NotImplementedError

    def outline(self) -> np.ndarray:
        """Closed boundary as ``(k, 2)`` points, for drawing."""
        raise NotImplementedError

    @property
    def sd_function(self) -> ca.Function:
        if not hasattr(self, "_sd_fn"):
            p = ca.SX.sym("p", 2)
            self._sd_fn = ca.Function(type(self).__name__.lower() + "_sd", [p], [self.sd_expr(p)])
        return self._sd_fn

    def signed_distance(self, points) -> np.ndarray:
        """Signed distance of ``(m, >=2)`` points (negative inside)."""
        pts = np.atleast_2d(np.asarray(points, dtype=float))[:, :2]
        if pts.shape[0] == 0:
            return np.zeros(0)
        return np.array(self.sd_function.map(pts.shape[0])(pts.T)).ravel()

    def contains(self, points, tol: float = 0.0) -> np.ndarray:
        """Boolean mask of points inside the shape (or within ``tol`` of it)."""
        return self.signed_distance(points) <= tol

    def area(self) -> float:
        o = self.outline()
        return 0.5 * abs(np.dot(o[:, 0], np.roll(o[:, 1], -1)) - np.dot(o[:, 1], np.roll(o[:, 0], -1)))


class Box(Shape):
    """Axis-aligned rectangle given by its centre and full ``size`` (width, height)."""

    def __init__(self, center, size):
        self.center = _vec2(center, "Box center")
        self.size = _vec2(size, "Box size")
        if np.any(self.size <= 0):
            raise ValueError(f"Box size must be positive, got {self.size}")

    def sd_expr(self, p):
        q = ca.fabs(p - self.center) - self.size / 2
        outside = _norm(ca.sumsqr(ca.fmax(q, 0)))  # distance to the box; 0 inside
        return outside + ca.fmin(ca.fmax(q[0], q[1]), 0)

    def outline(self):
        hx, hy = self.size / 2
        c = self.center
        return c + np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])


class Disc(Shape):
    """Disc of ``radius`` around ``center``."""

    def __init__(self, center, radius: float):
        self.center = _vec2(center, "Disc center")
        if not radius > 0:
            raise ValueError(f"Disc radius must be positive, got {radius}")
        self.radius = float(radius)

    def sd_expr(self, p):
        return _norm(ca.sumsqr(p - self.center)) - self.radius

    def outline(self):
        t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        return self.center + self.radius * np.c_[np.cos(t), np.sin(t)]


class Polygon(Shape):
    """Any simple polygon (convex or not) from its vertices in order."""

    def __init__(self, vertices):
        v = np.array(vertices, dtype=float)
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
            raise ValueError("Polygon vertices must be an (k >= 3, 2) array")
        if not np.all(np.isfinite(v)):
            raise ValueError("Polygon vertices must be finite")
        self.vertices = v

    def sd_expr(self, p):
        a = self.vertices
        b = np.roll(a, -1, axis=0)
        dist2 = []
        crossings = 0
        for ai, bi in zip(a, b):
            e = bi - ai
            t = ca.fmin(ca.fmax(ca.dot(p - ai, e) / np.dot(e, e), 0), 1)
            dist2.append(ca.sumsqr(p - ai - t * e))
            if ai[1] != bi[1]:  # horizontal edges never cross the ray
                straddles = (ai[1] > p[1]) != (bi[1] > p[1])
                x_cross = ai[0] + e[0] * (p[1] - ai[1]) / e[1]
                crossings = crossings + ca.logic_and(straddles, p[0] < x_cross)
        dist = _norm(ca.mmin(ca.vertcat(*dist2)))  # exact distance to the boundary
        inside = ca.fmod(crossings, 2)
        return dist * (1 - 2 * inside)

    def outline(self):
        return self.vertices.copy()


def square(center, side: float) -> Box:
    """An axis-aligned square."""
    return Box(center, (side, side))


def cross(center, span: float, width: float) -> Polygon:
    """A plus-shaped cross: two bars ``span`` long and ``width`` wide, as one polygon."""
    if not 0 < width < span:
        raise ValueError("a cross needs 0 < width < span")
    h, w = span / 2, width / 2
    pts = [(w, h), (-w, h), (-w, w), (-h, w), (-h, -w), (-w, -w),
           (-w, -h), (w, -h), (w, -w), (h, -w), (h, w), (w, w)]
    return Polygon(np.asarray(pts) + _vec2(center, "cross center"))


def _norm(r2):
    """``sqrt(r2)`` for a squared length ``r2 >= 0``, with derivative 0 at ``r2 = 0``.

    A bare ``sqrt`` has an infinite derivative at 0, which the chain rule turns into NaN
    (0 * inf), even for a region term that is not active there.  Clamping ``r2`` to the
    smallest normal double keeps that derivative finite (and ``fmax`` passes on none of it
    below the clamp), and it changes no distance above 1.5e-154: a point exactly on the
    boundary reads 1.5e-154 away.  It adds one operation per shape; an ``if_else`` guard
    giving exactly 0 makes the bound region terms' graphs markedly bigger for large flocks.
    """
    return ca.sqrt(ca.fmax(r2, _SMALLEST_NORMAL))


def _vec2(value, what) -> np.ndarray:
    arr = np.array(value, dtype=float).ravel()  # a copy: later edits of value must not move the shape
    if arr.size == 1:
        arr = np.repeat(arr, 2)
    if arr.size != 2 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be two finite numbers, got {value!r}")
    return arr
