"""Paths for a cloth's pinned vertices that move: sampled from a time-sampled mesh of the
cloth (``pin_motion``: :func:`sampled_pins`) or carried by a body's surface (``pin_body``:
:class:`RiddenPath`).  Either becomes an :class:`~..models.constraints.Attachment`, whose
step sets the pinned vertices' velocities so they reach the path's next position exactly
(positions and the velocities they imply agree).

A pinned vertex is no particle of any contact: the hold holds free particles only, and a
penalty spring on a pinned vertex acts on its own prescribed row, which the step's filter
drops; so a body a pin rides on never pushes the pin off its path, while the free
neighbours still collide with it.  Errors are :class:`~..meshes.MeshError` whose message
the caller prefixes with the option's name.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..meshes import MeshError, read_animated
from ..meshes.distance import MeshShape, pieces

ON_FRAME = 1e-9  # a time within this many frames of a sample is that sample, exactly
NOTED_GAP = 1e-3  # m: a start this far from the cloth's file is worth a note


@dataclass(frozen=True)
class SampledPath:
    """Positions ``frames`` ``(k, p, 3)`` one every ``dt`` s from t = 0: the sample itself
    at a sample's time (to round-off in t), linear between samples, the last held after it."""

    frames: np.ndarray
    dt: float

    def __call__(self, t: float) -> np.ndarray:
        s = min(max(float(t) / self.dt, 0.0), len(self.frames) - 1.0)
        k = int(round(s))
        if abs(s - k) <= ON_FRAME:
            return self.frames[k]
        k = min(int(s), len(self.frames) - 2)
        return self.frames[k] + (s - k) * (self.frames[k + 1] - self.frames[k])


def sampled_pins(path, n: int, pinned, steps: int, dt: float) -> tuple[SampledPath, list]:
    """``(path, notes)``: the pinned vertices' positions at frames 0..steps of the
    time-sampled mesh file ``path`` (a PC2 cache beside its ``NAME_rest.obj`` at one frame
    per ``dt``, or USD with time samples), read by the bodies' reader
    (:func:`~..meshes.read_animated`).  Refused (MeshError) when it is still, has another
    vertex count than the cloth's ``n``, samples at another rate than ``dt`` or has fewer
    than ``steps + 1`` frames; more are cut, with a note."""
    where = Path(path).expanduser()
    found = read_animated(where, fps=1 / dt)
    if found.frames is None:
        raise MeshError(f"{where} does not move: give a time-sampled mesh (USD with "
                        f"time samples, or a PC2 cache beside its NAME_rest.obj)")
    count = found.frames.shape[1]
    if count != n:
        raise MeshError(f"{where} has {count} vertices per frame, the cloth {n}: export the "
                        f"cloth's own mesh (same vertices in the same order)")
    gaps = np.diff(found.times)
    if not np.allclose(gaps, dt, rtol=1e-6, atol=0):
        raise MeshError(f"{where} is sampled every {gaps.min():.6g}..{gaps.max():.6g} s, the "
                        f"frame time dt is {dt:.6g} s: export one sample per frame, or set "
                        f"dt to the file's frame time")
    frames, notes = found.frames, []
    if len(frames) < steps + 1:
        raise MeshError(f"{where} has {len(frames)} frames (0..{len(frames) - 1}), the run "
                        f"needs {steps + 1} (frames 0..{steps}): export the whole shot, or "
                        f"lower steps to {len(frames) - 1}")
    if len(frames) > steps + 1:
        notes.append(f"pin_motion: {where} has {len(frames)} frames; the first {steps + 1} "
                     f"(0..{steps}) are used")
    return SampledPath(np.array(frames[:steps + 1][:, pinned]), float(dt)), notes


def start_gap_note(path_start, cloth_vertices, pinned, option: str) -> list:
    """A note when the pins' start ``path_start`` is more than :data:`NOTED_GAP` from the
    cloth file's pinned vertices (they start where the path says)."""
    gap = float(np.linalg.norm(path_start - cloth_vertices[pinned], axis=1).max(initial=0))
    if gap <= NOTED_GAP:
        return []
    return [f"{option}: the pinned vertices start where it puts them at frame 0, up to "
            f"{1e3 * gap:.4g} mm from the cloth file's vertices"]


class RiddenPath:
    """Points carried by a :class:`~..models.contact.colliders.MeshBody`'s surface: each
    point's closest triangle at t = 0, its closest point there (barycentric weights) and its
    offset from that point in the triangle's own frame (edge, normal x edge, normal), so the
    offset along the normal is kept as the body moves and turns, and the points at t = 0
    are the given ones (to round-off)."""

    def __init__(self, body, points):
        points = np.asarray(points, dtype=float)
        vertices = body.world_vertices(0.0)
        found = MeshShape(vertices, body.faces, pieces(body.faces, len(vertices))).closest(points)
        self.body, self.corners = body, np.asarray(found.corners, np.intp)
        self.weights = np.asarray(found.weights, float)
        origin, frame = self._frames(vertices)
        self.offsets = np.einsum("kij,kj->ki", frame, points - origin)

    def _frames(self, vertices):
        """Each point's closest point and its triangle's frame (rows: edge, normal x edge,
        normal), in the world, for the body's ``vertices``."""
        tri = vertices[self.corners]
        origin = np.einsum("kj,kjd->kd", self.weights, tri)
        edge = tri[:, 1] - tri[:, 0]
        normal = np.cross(edge, tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        edge /= np.linalg.norm(edge, axis=1, keepdims=True)
        return origin, np.stack([edge, np.cross(normal, edge), normal], axis=1)

    def __call__(self, t: float) -> np.ndarray:
        origin, frame = self._frames(self.body.world_vertices(float(t)))
        return origin + np.einsum("kij,ki->kj", frame, self.offsets)
