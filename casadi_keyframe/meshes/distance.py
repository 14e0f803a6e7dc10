r"""Closest points on a triangle mesh, signed, and the feature each lies on: what a mesh
body's contact needs (:class:`~casadi_keyframe.models.contact.colliders.MeshBody`).

libigl's AABB tree finds each point's closest point on the triangles.  The sign comes from
the pseudonormal of the feature the closest point lies on (a face's normal, an edge's mean
of its faces' normals, a vertex's angle-weighted normal; Baerentzen and Aanaes), which is
libigl's pseudonormal test: exact inside and outside for a closed mesh; on an open mesh it
says which side of the surface a point is on (behind an open mesh is inside).  A point a
caller needs only if it is near (within its reach) is spared the tree's query when it is
farther (:meth:`MeshShape.lower_bounds`: the distance to the nearest piece's bounding box
or sphere, whichever is farther): it gets a stand-in, a plane facing it at that distance.  A mesh of
several pieces (a character's separate limbs) is their union: a point's signed distance is
its least over the pieces.  The feature is the face's interior, one of its edges or one of
its vertices, as IPC's point-triangle distance types; within it the distance is smooth.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

MISSING = ("mesh bodies need libigl: pip install 'casadi_keyframe[bodies]' (or pip install "
           "libigl)")
ON_EDGE = 1e-9  # a barycentric weight below this puts the closest point on the opposite edge
FLAT = 1e-6  # m: closer than this to an edge or vertex, the feature is its tangent plane
FACE, EDGE, VERTEX = 0, 1, 2


def require_igl():
    """The ``igl`` module, or an ImportError naming the extra that installs it."""
    try:
        import igl
    except ImportError:
        raise ImportError(MISSING) from None
    return igl


@dataclass(frozen=True)
class Closest:
    """The closest features of k points: ``distance`` (k,) signed (negative inside),
    ``point`` (k, 3) on the surface, ``kind`` (k,) FACE, EDGE or VERTEX, ``flat`` (k,) whether
    the feature is taken as a plane (a face, or a point within :data:`FLAT` of an edge or
    vertex), ``edge`` (k, 3) an edge's unit direction (else zero), ``normal`` (k, 3) the
    plane's normal where flat (the pseudonormal), ``side`` (k,) +1 or -1, ``corners`` (k, 3)
    the face's vertices, ``weights`` (k, 3) the closest point's barycentric weights in it
    and ``gradients`` (k, 3, 3) each weight's gradient in the point, within the feature."""

    distance: np.ndarray
    point: np.ndarray
    kind: np.ndarray
    flat: np.ndarray
    edge: np.ndarray
    normal: np.ndarray
    side: np.ndarray
    corners: np.ndarray
    weights: np.ndarray
    gradients: np.ndarray


class MeshShape:
    """A triangle mesh in one shape (``vertices`` (v, 3), ``faces`` (f, 3)) ready for
    :meth:`closest`; ``pieces`` (from :func:`pieces`) are the face lists of its connected
    parts."""

    def __init__(self, vertices, faces, pieces):
        igl = require_igl()
        self.vertices = np.ascontiguousarray(vertices, dtype=float)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.trees = []
        for piece in pieces:
            tree = igl.AABB()
            tree.init(self.vertices, self.faces[piece])
            self.trees.append((tree, self.faces[piece], piece))
        self.face_normals, self.vertex_normals, self.edge_keys, self.edge_normals = \
            _pseudonormals(self.vertices, self.faces)
        used = [np.unique(self.faces[piece]) for piece in pieces]
        self.boxes = np.array([[self.vertices[u].min(0), self.vertices[u].max(0)]
                               for u in used])  # (pieces, 2, 3)
        self.centres = self.boxes.mean(1)
        self.radii = np.array([np.linalg.norm(self.vertices[u] - c, axis=1).max()
                               for u, c in zip(used, self.centres)])

    def bounds(self, points):
        """``(bound (k,), normal (k, 3))``: each point's lower bound of its distance to the
        mesh (:meth:`lower_bounds`) and the direction of its nearest bounding box or sphere
        (the one that gives the bound), from that bound to the point."""
        p = np.asarray(points, float)[:, None, :]
        box = p - np.clip(p, self.boxes[None, :, 0], self.boxes[None, :, 1])
        ball = p - self.centres[None]
        box_size, ball_size = np.linalg.norm(box, axis=2), np.linalg.norm(ball, axis=2)
        bound = np.maximum(box_size, ball_size - self.radii[None])
        nearest = bound.argmin(1)
        k = np.arange(len(bound))
        use_ball = (ball_size - self.radii[None] >= box_size)[k, nearest]
        gap = np.where(use_ball[:, None], ball[k, nearest], box[k, nearest])
        size = np.where(use_ball, ball_size[k, nearest], box_size[k, nearest])
        return bound[k, nearest], gap / np.maximum(size, 1e-300)[:, None]

    def lower_bounds(self, points) -> np.ndarray:
        """``(k,)``: a lower bound of each point's distance to the mesh (over the pieces,
        the least of the distances to each one's bounding box and sphere, the larger)."""
        return self.bounds(points)[0]

    def closest(self, points, near=None, bounds=None) -> Closest:
        """Each point's closest feature (over every piece, the least signed distance); with
        ``near`` ``(k,)`` bools, only those points' (the others get a stand-in: module
        docstring; ``bounds``: :meth:`bounds` of the points, if known)."""
        p = np.ascontiguousarray(points, dtype=float)
        if near is not None and not near.all():
            return self._stand_ins(p, near, self.bounds(p) if bounds is None else bounds)
        best = None
        for tree, faces, piece in self.trees:
            _, face, point = tree.squared_distance(self.vertices, faces, p)
            found = self._features(p, piece[face], point)
            if best is None:
                best = found
            else:
                nearer = found.distance < best.distance
                best = Closest(*(np.where(nearer.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)
                                 for a, b in zip(vars(found).values(), vars(best).values())))
        return best

    def _stand_ins(self, p, near, bounds) -> Closest:
        """:meth:`closest` of the ``near`` points; the others get a stand-in: the plane
        at their lower bound's distance (``bounds``: :meth:`bounds`), facing them."""
        k = len(p)
        bound, normal = bounds
        zero = np.zeros((k, 3))
        out = Closest(bound, p - bound[:, None] * normal, np.full(k, FACE), np.ones(k, bool),
                      zero, normal, np.ones(k), np.zeros((k, 3), np.int64),
                      np.tile([1.0, 0, 0], (k, 1)), np.zeros((k, 3, 3)))
        if near.any():
            found = self.closest(p[near])
            for a, b in zip(vars(out).values(), vars(found).values()):
                a[near] = b
        return out

    def _features(self, p, face, point) -> Closest:
        corners = self.faces[face]
        tri = self.vertices[corners]
        weights = _barycentric(point, tri)
        off = weights <= ON_EDGE
        count = off.sum(1)
        kind = np.where(count == 0, FACE, np.where(count == 1, EDGE, VERTEX))
        weights = np.where(off, 0.0, weights)
        weights /= weights.sum(1, keepdims=True)
        k = len(p)
        # an edge's ends: the two corners still weighted; a vertex: the one weighted corner
        order = np.argsort(off, axis=1, kind="stable")
        i, j = corners[np.arange(k), order[:, 0]], corners[np.arange(k), order[:, 1]]
        span = self.vertices[j] - self.vertices[i]
        length = np.linalg.norm(span, axis=1)
        edge = np.where((kind == EDGE)[:, None], span / np.maximum(length, 1e-300)[:, None], 0.0)
        pseudo = self.face_normals[face].copy()
        on_edge, on_vertex = kind == EDGE, kind == VERTEX
        pseudo[on_edge] = self._edge_normal(i[on_edge], j[on_edge])
        pseudo[on_vertex] = self.vertex_normals[i[on_vertex]]
        gap = p - point
        size = np.linalg.norm(gap, axis=1)
        side = np.where(np.einsum("ka,ka->k", gap, pseudo) >= 0, 1.0, -1.0)
        flat = (kind == FACE) | (size < FLAT)
        gradients = np.zeros((k, 3, 3))
        gradients[kind == FACE] = _weight_gradients(tri[kind == FACE],
                                                    self.face_normals[face[kind == FACE]])
        rows = np.flatnonzero(on_edge)
        along = edge[on_edge] / np.maximum(length[on_edge], 1e-300)[:, None]
        gradients[rows, order[rows, 0]] = -along
        gradients[rows, order[rows, 1]] = along
        return Closest(side * size, point, kind, flat, np.where(flat[:, None], 0.0, edge),
                       np.where(flat[:, None], pseudo, 0.0), side, corners, weights, gradients)

    def _edge_normal(self, i, j):
        key = np.minimum(i, j) * len(self.vertices) + np.maximum(i, j)
        return self.edge_normals[np.searchsorted(self.edge_keys, key)]


def pieces(faces, n: int) -> list[np.ndarray]:
    """The face indices of each connected part of a mesh of ``n`` vertices."""
    faces = np.asarray(faces, np.int64)
    rows = np.repeat(faces[:, 0], 2)
    cols = faces[:, 1:].ravel()
    graph = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    of_face = label[faces[:, 0]]
    return [np.flatnonzero(of_face == c) for c in np.unique(of_face)]


def _barycentric(point, tri):
    """Barycentric weights (k, 3) of points on the triangles ``tri`` (k, 3, 3)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, point - a
    d00, d01, d11 = (np.einsum("ka,ka->k", u, w) for u, w in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ka,ka->k", v2, v0), np.einsum("ka,ka->k", v2, v1)
    denom = d00 * d11 - d01 * d01
    wb = (d11 * d20 - d01 * d21) / denom
    wc = (d00 * d21 - d01 * d20) / denom
    return np.c_[1 - wb - wc, wb, wc]


def _weight_gradients(tri, normals):
    """Each corner's barycentric weight's gradient in the face's plane, (k, 3, 3): corner
    a's is ``n x (c - b) / (2 area)``."""
    twice = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    out = np.empty_like(tri)
    for corner in range(3):
        b, c = tri[:, (corner + 1) % 3], tri[:, (corner + 2) % 3]
        out[:, corner] = np.cross(normals, c - b) / twice[:, None]
    return out


def _pseudonormals(vertices, faces):
    """``(face normals, vertex normals (angle-weighted), edge keys (sorted), edge normals)``."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_normals = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
    vertex_normals = np.zeros_like(vertices)
    for corner in range(3):
        u = tri[:, (corner + 1) % 3] - tri[:, corner]
        w = tri[:, (corner + 2) % 3] - tri[:, corner]
        cos = np.einsum("ka,ka->k", u, w) / np.maximum(
            np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
        np.add.at(vertex_normals, faces[:, corner],
                  np.arccos(np.clip(cos, -1, 1))[:, None] * face_normals)
    vertex_normals /= np.maximum(np.linalg.norm(vertex_normals, axis=1), 1e-300)[:, None]
    n = len(vertices)
    ends = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys = ends.min(1) * n + ends.max(1)
    unique, where = np.unique(keys, return_inverse=True)
    edge_normals = np.zeros((unique.size, 3))
    np.add.at(edge_normals, where, np.tile(face_normals, (3, 1)))
    edge_normals /= np.maximum(np.linalg.norm(edge_normals, axis=1), 1e-300)[:, None]
    return face_normals, vertex_normals, unique, edge_normals
