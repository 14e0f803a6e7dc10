"""Plotting-free geometry that pictures and exports share: colliders at a time, circles,
capsule surfaces and plane patches, the triangles of a surface grid, and the rigid motion
that best carries one set of points onto another (keyframes and scenes measure by it).

Both the matplotlib renderers (:mod:`.render`) and the exporters (:mod:`.export`) draw or
write the same bodies, so they read them here, once, without importing a plotting library.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .models.contact.colliders import Plane, Sphere


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


def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """``(2 (rows-1) (cols-1), 3)`` vertex indices triangulating a ``rows x cols`` grid of
    points stored row by row (as :func:`capsule_grid`'s, reshaped to ``(-1, 3)``)."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (r * cols + c).ravel()
    b, d = a + 1, a + cols
    return np.r_[np.c_[a, b, d + 1], np.c_[a, d + 1, d]]


def body_geometry(body, t: float):
    """``("plane", point, normal)``, ``("round", a, b, radius)`` (a sphere is a round body
    with ``a == b``) or ``("mesh", vertices, faces)`` from ``body.geometry(t)``."""
    if body.kind == "mesh":
        vertices, faces = body.geometry(t)
        return "mesh", vertices, faces
    g = [np.asarray(p, dtype=float) for p in body.geometry(t)]
    if isinstance(body, Plane):
        return "plane", g[0], g[1]
    if isinstance(body, Sphere):  # center, radius, velocity
        return "round", g[0], g[0], float(g[1][0])
    return "round", g[0], g[1], float(g[2][0])  # Capsule: a, b, radius, va, vb


def plane_patch(point, normal, mid, half: float) -> np.ndarray:
    """The 4 corners of a square of half-side ``half`` on the plane, centred below ``mid``."""
    n, e1, e2 = basis(normal)
    c = mid - np.dot(mid - point, n) * n
    return np.array([c + half * (s * e1 + r * e2) for s, r in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def moves(body, times) -> bool:
    """Whether ``body``'s geometry changes over ``times``."""
    first = body_geometry(body, times[0])
    return any(not all(np.array_equal(p, q) for p, q in zip(first[1:], body_geometry(body, t)[1:]))
               for t in times[1:])


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
