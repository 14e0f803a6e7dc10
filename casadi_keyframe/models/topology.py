"""The structure of a cloth: springs of a grid or a triangle mesh, and masses lumped by area."""
from __future__ import annotations

import numpy as np

from .springs import BEND, SHEAR, STRETCH


def grid_topology(rows: int, cols: int):
    """Spring index pairs by kind and the quads of a rows x cols grid (k = r cols + c)."""
    idx = np.arange(rows * cols).reshape(rows, cols)

    def pairs(a, b):
        return np.stack([a.ravel(), b.ravel()], axis=1)

    stretch = np.vstack([pairs(idx[:, :-1], idx[:, 1:]), pairs(idx[:-1, :], idx[1:, :])])
    shear = np.vstack([pairs(idx[:-1, :-1], idx[1:, 1:]), pairs(idx[:-1, 1:], idx[1:, :-1])])
    bend = np.vstack([pairs(idx[:, :-2], idx[:, 2:]), pairs(idx[:-2, :], idx[2:, :])])
    a, b, c, e = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    quads = np.stack([a, c, e, b], -1).reshape(-1, 4)
    return {STRETCH: stretch, SHEAR: shear, BEND: bend}, quads


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """The unique undirected edges ``(E, 2)``, smaller index first, of triangles ``faces``."""
    faces = np.asarray(faces, dtype=np.intp)
    return np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                             faces[:, [2, 0]]]), axis=1), axis=0)


def mesh_hinges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(edges, hinges)`` of triangles ``faces``: the unique edges ``(E, 2)`` (smaller index
    first, sorted) and per interior edge its hinge ``(a, b, c, d)``, the edge's ends a < b
    and the vertices c and d opposite it in its two triangles (ValueError if an edge has
    more than two)."""
    faces = np.asarray(faces, dtype=np.intp)
    half = np.concatenate([faces[:, [0, 1, 2]], faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])
    edges = np.sort(half[:, :2], axis=1)  # each half-edge with its opposite vertex half[:, 2]
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, opposite = edges[order], half[order, 2]
    first = np.ones(len(edges), bool)
    first[1:] = np.any(edges[1:] != edges[:-1], axis=1)
    shared = np.flatnonzero(~first)  # second half-edge of an interior edge
    if np.any(np.bincount(np.cumsum(first) - 1) > 2):
        raise ValueError("non-manifold mesh: an edge is shared by more than two faces")
    hinges = np.stack([edges[shared, 0], edges[shared, 1], opposite[shared - 1],
                       opposite[shared]], axis=1)
    return edges[first], hinges


def mesh_topology(faces: np.ndarray):
    """Stretch springs on the mesh edges, bend springs across each interior edge (between
    the vertices of its hinge opposite it)."""
    edges, hinges = mesh_hinges(faces)
    return {STRETCH: edges, SHEAR: np.zeros((0, 2), int), BEND: hinges[:, 2:]}


def lumped_masses(vertices: np.ndarray, faces: np.ndarray, total: float) -> np.ndarray:
    """Each vertex gets an equal share of the area of its polygons (triangles, or quads for
    a grid, which keeps a grid's masses symmetric); scaled to ``total`` kg."""
    k = faces.shape[1]
    a = vertices[faces[:, 0]]
    area = sum(0.5 * np.linalg.norm(np.cross(vertices[faces[:, q]] - a,
                                             vertices[faces[:, q + 1]] - a), axis=1)
               for q in range(1, k - 1))  # fan triangulation (planar, convex quads)
    share = np.bincount(faces.ravel(), np.repeat(area / k, k), minlength=len(vertices))
    if np.any(share <= 0):
        raise ValueError("every vertex must belong to a face of positive area "
                         "(remove unused vertices or degenerate triangles)")
    return total * share / share.sum()
