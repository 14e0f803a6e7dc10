"""Carry controls from one mesh of a cloth to another mesh of the same cloth (coarse to fine
in space).

Each particle of the target mesh takes its rest position's closest point on the source
mesh's rest surface, and the controls there by barycentric interpolation: initial
velocities as velocities, step forces as forces per unit mass (accelerations), so the same
motion is asked of the same piece of cloth at any resolution.  Then a uniform correction
over the target's controlled particles restores the source's total: its momentum (initial
velocities) or every step's total force (step forces), i.e. the impulse, exactly.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..controls import InitialVelocity, StepForces
from ..models.base import Surface

def mesh_interpolation(vertices, faces, points) -> sp.csr_matrix:
    """``(len(points), len(vertices))`` barycentric weights of each point's closest point on
    the triangle mesh ``(vertices, faces)``: rows sum to one, at most three entries each."""
    vertices, faces = np.asarray(vertices, float), np.asarray(faces, np.intp)
    points = np.asarray(points, float)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"interpolation needs a triangle mesh, got faces of shape {faces.shape}")
    corners = vertices[faces]
    centroids = corners.mean(axis=1)
    reach = np.max(np.linalg.norm(corners - centroids[:, None], axis=2))
    tree = cKDTree(centroids)
    # the closest point lies on a triangle whose centroid is within the nearest centroid's
    # distance plus the largest centroid-to-corner distance: those are the candidates
    nearest, _ = tree.query(points)
    found = tree.query_ball_point(points, nearest + reach * (1 + 1e-9) + 1e-12)
    point = np.repeat(np.arange(len(points)), [len(f) for f in found])
    tri = np.concatenate([np.asarray(f, np.intp) for f in found])
    weights, dist2 = _closest_on_triangles(points[point], corners[tri])
    order = np.lexsort((dist2, point))  # per point, the nearest candidate first
    first = order[np.r_[0, np.flatnonzero(np.diff(point[order])) + 1]]
    rows = point[first]
    P = sp.csr_matrix((weights[first].ravel(), (np.repeat(rows, 3), faces[tri[first]].ravel())),
                      shape=(len(points), len(vertices)))
    P.eliminate_zeros()
    return P


def _closest_on_triangles(p, tri):
    """Barycentric weights ``(..., 3)`` of the closest point to ``p`` on each triangle
    ``tri`` ``(..., 3, 3)``, and the squared distances: the interior projection when it falls
    inside, else the best of the three edges' clamped projections."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    e1, e2, d = b - a, c - a, p - a
    d11, d12, d22 = (np.sum(e1 * e1, -1), np.sum(e1 * e2, -1), np.sum(e2 * e2, -1))
    d1, d2 = np.sum(d * e1, -1), np.sum(d * e2, -1)
    det = d11 * d22 - d12 ** 2
    safe = np.where(det > 0, det, 1.0)
    s, t = (d22 * d1 - d12 * d2) / safe, (d11 * d2 - d12 * d1) / safe
    inside = (det > 0) & (s >= 0) & (t >= 0) & (s + t <= 1)
    candidates = [np.stack([1 - s - t, s, t], -1)]
    for i, j in ((0, 1), (1, 2), (2, 0)):
        q, r = tri[..., i, :], tri[..., j, :]
        edge = r - q
        length2 = np.sum(edge * edge, -1)
        f = np.clip(np.sum((p - q) * edge, -1) / np.where(length2 > 0, length2, 1.0), 0, 1)
        w = np.zeros(s.shape + (3,))
        w[..., i], w[..., j] = 1 - f, f
        candidates.append(w)
    weights = np.stack(candidates, -2)  # (..., 4, 3)
    closest = np.einsum("...cv,...vd->...cd", weights, tri)
    dist2 = np.sum((closest - p[..., None, :]) ** 2, -1)
    dist2[..., 0] = np.where(inside, dist2[..., 0], np.inf)
    pick = np.argmin(dist2, -1)
    take = np.take_along_axis
    return (take(weights, pick[..., None, None], -2)[..., 0, :],
            take(dist2, pick[..., None], -1)[..., 0])


def carry_to_mesh(source, u, target) -> np.ndarray:
    """The controls ``u`` of problem ``source`` as controls of problem ``target``: the same
    cloth on another mesh (see the module), and on ``target``'s time grid."""
    kind = type(source.controls)
    if kind not in (StepForces, InitialVelocity) or type(target.controls) is not kind:
        raise ValueError(
            f"carrying controls between meshes knows per-step forces and initial velocities "
            f"of the same kind on both meshes; got {type(source.controls).__name__} to "
            f"{type(target.controls).__name__}")
    for which, p in (("source", source), ("target", target)):
        if not isinstance(p.model, Surface):
            raise ValueError(f"the {which} problem {p.name!r} has no mesh (a surface): "
                             "only a cloth's controls carry between meshes")
    u = source.controls.check(u)
    if kind is StepForces:
        u = source.controls.resample(u, target.steps)
        steps = target.steps
        forces = np.zeros((steps, source.model.n, 3))
        forces[:, source.controls.idx] = u.reshape(steps, -1, 3)
        per_mass = forces / source.model.masses[:, None]
    else:
        per_mass = source.controls.velocity_offset(u)[None]
    mass = source.model.masses[source.controls.idx]
    mean = np.einsum("skd,k->sd", per_mass[:, source.controls.idx], mass) / mass.sum()
    P = mesh_interpolation(source.model.rest_positions, source.model.faces,
                           target.model.rest_positions)
    idx = target.controls.idx
    P = _among(P[idx], source.controls.idx)
    moved = np.stack([P @ field[source.controls.idx] for field in per_mass])  # (s, k, 3)
    m = target.model.masses[idx]
    moved += (mean - np.einsum("skd,k->sd", moved, m) / m.sum())[:, None, :]
    out = moved * m[:, None] if kind is StepForces else moved[0]
    return np.clip(target.controls.check(out.ravel()), *target.bounds())


def _among(P, controlled) -> sp.csr_matrix:
    """The interpolation ``P`` from the controlled source particles only, each row's weights
    scaled to sum to one again: an uncontrolled particle (pinned, sewn on) has no control to
    lend its neighbours, rather than a zero one.  A row with none stays zero (the momentum
    correction still reaches it)."""
    P = P[:, controlled].tocsr()
    sums = np.asarray(P.sum(axis=1)).ravel()
    return sp.diags(np.divide(1.0, sums, out=np.zeros_like(sums), where=sums > 0)) @ P
