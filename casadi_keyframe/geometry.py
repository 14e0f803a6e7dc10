"""Plotting-free geometry that pictures and exports share: the typed shapes of colliders at
a time (:class:`Patch`, :class:`Round`, :class:`TriangleMesh`), circles, capsule surfaces
and plane patches, the polygons of a surface grid, and the rigid motion that best carries
one set of points onto another (keyframes and scenes measure by it).

A collider gives its shape at time t (``body.shape(t)``, :mod:`.models.contact.colliders`);
the matplotlib renderers (:mod:`.render`) and the exporters (:mod:`.export`) draw or write
any shape through what it says of itself (:class:`BodyShape`: its extent, its polygons,
whether it lies beneath), so they never ask which kind it is, and read it here, once,
without importing a plotting library.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.spatial.transform import Rotation


def basis(normal):
    """Unit ``normal`` and two unit vectors spanning the plane orthogonal to it."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n) if np.linalg.norm(n) > 1e-12 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return n, e1, np.cross(n, e1)


def circle(center, normal, radius, k: int = 64) -> np.ndarray:
    """``(k, 3)`` points of a closed circle (the first point repeated last)."""
    _, e1, e2 = basis(normal)
    phi = np.linspace(0, 2 * np.pi, k)
    return np.asarray(center, float) + radius * (np.outer(np.cos(phi), e1)
                                                 + np.outer(np.sin(phi), e2))


def capsule_grid(a, b, radius, k: int = 12) -> np.ndarray:
    """``(2k, 2k, 3)`` grid over a capsule's surface (a sphere when ``a == b``)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n, e1, e2 = basis(b - a)
    theta = np.r_[np.linspace(-np.pi / 2, 0, k), np.linspace(0, np.pi / 2, k)]
    ends = np.r_[np.tile(a, (k, 1)), np.tile(b, (k, 1))]
    phi = np.linspace(0, 2 * np.pi, 2 * k)
    ring = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    return (ends[:, None] + radius * (np.cos(theta)[:, None, None] * ring[None]
                                      + np.sin(theta)[:, None, None] * n))


def grid_faces(rows: int, cols: int) -> np.ndarray:
    """``((rows-1) (cols-1), 4)`` vertex indices of the quads of a ``rows x cols`` grid of
    points stored row by row (as :func:`capsule_grid`'s, reshaped to ``(-1, 3)``)."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (r * cols + c).ravel()
    return np.c_[a, a + cols, a + cols + 1, a + 1]


def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """``(2 (rows-1) (cols-1), 3)`` vertex indices triangulating a ``rows x cols`` grid of
    points stored row by row (as :func:`capsule_grid`'s, reshaped to ``(-1, 3)``)."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (r * cols + c).ravel()
    b, d = a + 1, a + cols
    return np.r_[np.c_[a, b, d + 1], np.c_[a, d + 1, d]]


def plane_patch(point, normal, mid, half: float) -> np.ndarray:
    """The 4 corners of a square of half-side ``half`` on the plane, centred below ``mid``."""
    n, e1, e2 = basis(normal)
    c = mid - np.dot(mid - point, n) * n
    return np.array([c + half * (s * e1 + r * e2) for s, r in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


class BodyShape:
    """What a collider looks like at one time, for pictures and exports: a typed shape knows
    its extent, the polygons that show it and whether it lies ``beneath`` the rest (an
    unbounded plane, drawn as a square sized to what is around it, under everything).
    ``mid`` and ``half`` are the middle and half-size of that square; ``detail`` how finely
    a curved surface is cut.  An output with a better form for a shape (USD's analytic
    sphere) keys it by the shape's type; any other shape it writes as its :meth:`polygons`."""

    beneath = False

    def extent(self, mid) -> np.ndarray:
        """``(k, 3)`` points that bound the shape (a plane: its point below ``mid``)."""
        raise NotImplementedError

    def polygons(self, mid=None, half=None, detail: int = 8):
        """``(vertices (v, 3), faces (f, k))``: the polygons (triangles or quads) that show it."""
        raise NotImplementedError

    def triangles(self, mid=None, half=None, detail: int = 8):
        """``(vertices, triangles (f, 3))``: :meth:`polygons` cut into triangles."""
        vertices, faces = self.polygons(mid, half, detail)
        if faces.shape[1] == 3:
            return vertices, faces
        return vertices, np.vstack([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])

    def same(self, other) -> bool:
        """Whether ``other`` is this shape at the same place."""
        return type(other) is type(self) and all(
            np.array_equal(getattr(self, f.name), getattr(other, f.name)) for f in fields(self))


@dataclass(frozen=True, eq=False)
class Patch(BodyShape):
    """An unbounded plane through ``point`` with ``normal``, shown as a square patch."""

    point: np.ndarray
    normal: np.ndarray

    beneath = True

    def extent(self, mid) -> np.ndarray:
        normal = self.normal[None] / np.linalg.norm(self.normal[None], axis=1, keepdims=True)
        return mid - np.sum((mid - self.point[None]) * normal, 1, keepdims=True) * normal

    def polygons(self, mid=None, half=None, detail: int = 8):
        return plane_patch(self.point, self.normal, mid, half), np.array([[0, 1, 2, 3]])


@dataclass(frozen=True, eq=False)
class Round(BodyShape):
    """A capsule from ``a`` to ``b`` of ``radius``; a sphere where they coincide."""

    a: np.ndarray
    b: np.ndarray
    radius: float

    @property
    def sphere(self) -> bool:
        return bool(np.array_equal(self.a, self.b))

    def extent(self, mid=None) -> np.ndarray:
        r = self.radius
        return np.array([self.a - r, self.a + r, self.b - r, self.b + r])

    def polygons(self, mid=None, half=None, detail: int = 8):
        grid = capsule_grid(self.a, self.b, self.radius, detail)
        return grid.reshape(-1, 3), grid_faces(*grid.shape[:2])

    def triangles(self, mid=None, half=None, detail: int = 8):
        grid = capsule_grid(self.a, self.b, self.radius, detail)
        return grid.reshape(-1, 3), grid_triangles(*grid.shape[:2])


@dataclass(frozen=True, eq=False)
class TriangleMesh(BodyShape):
    """A triangle mesh: ``vertices`` ``(v, 3)`` and ``faces`` ``(f, 3)``."""

    vertices: np.ndarray
    faces: np.ndarray

    def extent(self, mid=None) -> np.ndarray:
        return self.vertices

    def polygons(self, mid=None, half=None, detail: int = 8):
        return self.vertices, self.faces


def moves(shapes) -> bool:
    """Whether a body's ``shapes`` (one per time) differ."""
    return any(not shapes[0].same(shape) for shape in shapes[1:])


def best_rigid_motion(source, dest, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)``, the rotation and translation that carry the points ``source`` closest to
    ``dest`` (both ``(n, 3)``): they minimise ``sum_i w_i |dest_i - (R source_i + t)|^2``
    (Kabsch, weighted, centroids removed; a proper rotation, no reflection)."""
    w = np.ones(len(source)) if weights is None else np.asarray(weights, float)
    ca, cb = (np.average(np.asarray(p, float), axis=0, weights=w) for p in (source, dest))
    turn, _ = Rotation.align_vectors(np.asarray(dest, float) - cb,
                                     np.asarray(source, float) - ca, weights=w)
    R = turn.as_matrix()
    return R, cb - R @ ca
