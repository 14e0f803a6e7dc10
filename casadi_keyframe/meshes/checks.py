"""Checks a cloth mesh must pass before it becomes springs: triangles only (larger polygons
fanned, with a notice), every face of positive area, every vertex used, every edge shared by
at most two faces.  A body's mesh passes them too, and then :func:`check_body`: its faces
wound alike (turned where they are not, with a notice), a closed piece's facing out, an
open one noted (its inside is only a side).  A failure is a :class:`MeshError` that names
the file, what is wrong and where, and what to do about it."""
from __future__ import annotations

import numpy as np

from .mesh import Mesh

# a face whose area is below this fraction of the mean face area counts as degenerate
DEGENERATE_AREA = 1e-10


class MeshError(ValueError):
    """A mesh that cannot be read or cannot be a cloth; the message says why and how to fix it."""


def triangulate(polygons) -> tuple[np.ndarray, int]:
    """``(triangles (m, 3), polygons split)``: each polygon (a list of vertex indices, 3 or
    more) fanned from its first corner, ``(a, b, c, d) -> (a, b, c), (a, c, d)``.  The split
    depends on the indices only, so the same polygons give the same triangles in every file
    (what a target mesh's topology check needs); it suits planar convex polygons."""
    triangles, split = [], 0
    for poly in polygons:
        poly = [int(i) for i in poly]
        if len(poly) < 3:
            raise MeshError(f"a face has {len(poly)} corners; every face needs at least 3")
        split += len(poly) > 3
        triangles.extend((poly[0], poly[k], poly[k + 1]) for k in range(1, len(poly) - 1))
    return np.array(triangles, dtype=np.intp).reshape(-1, 3), split


def check_mesh(vertices, polygons, *, source=None, groups=None, first: int = 0,
               face_of=None, role: str = "cloth") -> Mesh:
    """The :class:`Mesh` of ``vertices`` ``(n, 3)`` and ``polygons`` (triangles or larger),
    checked as the module docstring says; ``source`` names the file in messages, which
    number vertices and faces as the file does, from ``first`` (OBJ counts from 1);
    ``face_of`` gives each polygon's face number in the file (0-based), where a reader
    split the file's faces before (default: the polygons are the file's faces); ``role``
    ("cloth" or "body") is what the messages say the mesh is for."""
    where = str(source) if source is not None else "mesh"
    numbers = Numbering(first)
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
        raise MeshError(f"{where}: needs at least 3 vertices with x, y, z; got an array of "
                        f"shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise MeshError(f"{where}: a vertex has a NaN or infinite coordinate (vertex "
                        f"{numbers.vertex(np.flatnonzero(~np.isfinite(v).all(1))[0])})")
    polygons = list(polygons)
    if not polygons:
        raise MeshError(f"{where}: has no faces; a {role} needs a surface (export the "
                        f"faces, not only the points)")
    faces, split = triangulate(polygons)
    owner = np.repeat(np.arange(len(polygons)) if face_of is None else np.asarray(face_of),
                      [max(len(p) - 2, 0) for p in polygons])
    outside = np.flatnonzero((faces < 0) | (faces >= len(v)))
    if outside.size:
        k = outside[0] // 3
        raise MeshError(f"{where}: face {numbers.face(owner[k])} refers to vertex "
                        f"{numbers.vertex(faces.flat[outside[0]])}, but the file has {len(v)} "
                        f"vertices ({numbers.span(len(v))})")
    _check_degenerate(v, faces, where, numbers.faces_of(owner, faces))
    _check_used(v, faces, where, numbers, role)
    _check_manifold(faces, where, numbers, role)
    notices = ((f"{where}: {split} of {len(polygons)} faces had more than 3 corners and were "
                f"split into triangles from their first corner",) if split else ())
    return Mesh(v, faces, dict(groups or {}), source, notices)


class Numbering:
    """Vertex and face numbers as a file counts them, from ``first`` (0, or 1 for OBJ)."""

    def __init__(self, first: int = 0):
        self.first = int(first)

    def vertex(self, i) -> int:
        return int(i) + self.first

    def face(self, k) -> int:
        return int(k) + self.first

    def span(self, n: int) -> str:
        return f"{self.first}..{n - 1 + self.first}"

    def faces_of(self, owner, faces):
        """``describe(k)``: triangle k as its file face's number and corner vertex numbers."""
        def describe(k) -> str:
            corners = " ".join(str(self.vertex(i)) for i in faces[k])
            return f"face {self.face(owner[k])} (vertices {corners})"
        return describe


def _check_degenerate(v, faces, where, describe):
    repeated = np.flatnonzero((faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
                              | (faces[:, 0] == faces[:, 2]))
    if repeated.size:
        raise MeshError(f"{where}: {repeated.size} face(s) repeat a vertex (first: "
                        f"{describe(repeated[0])}); merge or remove them (Blender: "
                        f"Mesh > Clean Up > Degenerate Dissolve)")
    area = 0.5 * np.linalg.norm(np.cross(v[faces[:, 1]] - v[faces[:, 0]],
                                         v[faces[:, 2]] - v[faces[:, 0]]), axis=1)
    flat = np.flatnonzero(area <= DEGENERATE_AREA * max(area.mean(), 1e-300))
    if flat.size:
        raise MeshError(f"{where}: {flat.size} face(s) have no area (first: "
                        f"{describe(flat[0])}, corners on one line); remove them "
                        f"(Blender: Mesh > Clean Up > Degenerate Dissolve)")


def _check_used(v, faces, where, numbers, role="cloth"):
    unused = np.setdiff1d(np.arange(len(v)), faces.ravel())
    if unused.size:
        why = ("a cloth particle needs a face to get a mass" if role == "cloth" else
               f"a {role}'s vertices are its surface's corners")
        raise MeshError(f"{where}: {unused.size} vertex/vertices belong to no face (first: "
                        f"vertex {numbers.vertex(unused[0])}); {why}: delete loose vertices "
                        f"(Blender: Mesh > Clean Up > Delete Loose)")


def _check_manifold(faces, where, numbers, role="cloth"):
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    crowded = np.flatnonzero(counts > 2)
    if crowded.size:
        a, b = (numbers.vertex(i) for i in unique[crowded[0]])
        raise MeshError(f"{where}: non-manifold: {crowded.size} edge(s) are shared by more "
                        f"than two faces (first: the edge between vertices {a} and {b}, in "
                        f"{int(counts[crowded[0]])} faces); a {role} is a surface whose edges "
                        f"join at most two faces: split or delete the extra faces (Blender: "
                        f"Select > Select All by Trait > Non Manifold)")


def check_body(mesh: Mesh) -> Mesh:
    """``mesh`` (checked by :func:`check_mesh`) as a body: the faces of each piece wound
    alike (a face wound against its neighbours turned, with a notice), each closed piece
    facing out (its volume positive; turned over otherwise, with a notice), and a notice
    for an open piece: its inside is only the side behind its faces, without end, which a
    solid body is not.  A piece that cannot be wound alike (a Moebius strip) is refused."""
    faces, where = mesh.faces.copy(), mesh.label()
    turned = _wind_alike(faces, where)
    notices = list(mesh.notices)
    if turned:
        notices.append(f"{where}: {turned} of {len(faces)} faces were wound against their "
                       f"neighbours (their normals pointing the other way) and were turned "
                       f"to agree")
    edges, counts = _edge_counts(faces)
    open_edges = edges[counts == 1]
    inward = 0
    for piece in _pieces(faces, len(mesh.vertices)):
        closed = (_edge_counts(faces[piece])[1] == 2).all()
        if closed and _volume(mesh.vertices, faces[piece]) < 0:
            faces[piece] = faces[piece][:, ::-1]
            inward += 1
    if inward:
        notices.append(f"{where}: {inward} closed piece(s) had their faces pointing inward; "
                       f"turned to point out (a body's normals point out of it)")
    if len(open_edges):
        first = 1 if str(where).lower().endswith(".obj") else 0  # as the file counts them
        a, b = open_edges[0] + first
        notices.append(f"{where}: open: {len(open_edges)} edge(s) belong to one face only "
                       f"(first: between vertices {a} and {b}), so it has no inside; the "
                       f"side behind its faces counts as inside, without end: a solid body "
                       f"needs a closed mesh (Blender: Select > Select All by Trait > Non "
                       f"Manifold, then Face > Fill)")
    return Mesh(mesh.vertices, faces, mesh.groups, mesh.source, tuple(notices))


def _edge_counts(faces):
    """The undirected edges of ``faces`` and how many faces use each."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    return np.unique(edges, axis=0, return_counts=True)


def _pieces(faces, n: int) -> list:
    """The faces of each connected piece, as index arrays."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.repeat(np.arange(len(faces)), 3)
    graph = coo_matrix((np.ones(rows.size), (rows, faces.ravel())),
                       shape=(len(faces), n)).tocsr()
    _, label = connected_components(graph @ graph.T, directed=False)
    return [np.flatnonzero(label == k) for k in np.unique(label)]


def _wind_alike(faces, where) -> int:
    """Turn (in place) the faces wound against the neighbours they share an edge with,
    each piece from its first face; the number turned."""
    m = len(faces)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(m), 3)
    key = np.sort(directed, 1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, directed, owner = key[order], directed[order], owner[order]
    pair = np.flatnonzero((key[1:] == key[:-1]).all(1))  # two faces on one edge
    a, b = owner[pair], owner[pair + 1]
    same = (directed[pair] == directed[pair + 1]).all(1)  # walked the same way: they disagree
    neighbours = [[] for _ in range(m)]
    for f, g, s in zip(a.tolist(), b.tolist(), same.tolist()):
        neighbours[f].append((g, s))
        neighbours[g].append((f, s))
    flip, piece = np.full(m, -1), np.full(m, -1)
    for seed in range(m):
        if flip[seed] >= 0:
            continue
        flip[seed], piece[seed], stack = 0, seed, [seed]
        while stack:
            f = stack.pop()
            for g, s in neighbours[f]:
                want = flip[f] ^ int(s)
                if flip[g] < 0:
                    flip[g], piece[g] = want, seed
                    stack.append(g)
                elif flip[g] != want:
                    raise MeshError(f"{where}: its faces cannot all be wound alike (a "
                                    f"one-sided surface, such as a Moebius strip, around "
                                    f"face {g}); a body needs two sides")
    turned = flip == 1
    for seed in np.unique(piece):  # each piece keeps the way most of its faces were wound
        mine = piece == seed
        if 2 * turned[mine].sum() > mine.sum():
            turned[mine] = ~turned[mine]
    faces[turned] = faces[turned][:, ::-1]
    return int(turned.sum())


def _volume(vertices, faces) -> float:
    """The signed volume a closed set of triangles bounds (positive: normals point out)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
