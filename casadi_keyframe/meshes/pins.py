"""Pinned particles of a cloth read from a file: vertex indices, a named vertex set of the
file, or the vertices inside a box."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import MeshError
from .mesh import Mesh


@dataclass(frozen=True)
class PinBox:
    """The vertices with ``lower <= x <= upper`` in every coordinate (metres, as the file)."""

    lower: tuple
    upper: tuple

    def __post_init__(self):
        lo, hi = (np.asarray(a, float) for a in (self.lower, self.upper))
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(np.r_[lo, hi])):
            raise MeshError(f"a pin box needs 3 finite lower and 3 finite upper coordinates, "
                            f"got {self.lower}, {self.upper}")
        if np.any(lo > hi):
            raise MeshError(f"a pin box's lower corner {tuple(lo)} must not exceed its upper "
                            f"corner {tuple(hi)} in any coordinate")
        object.__setattr__(self, "lower", tuple(lo))
        object.__setattr__(self, "upper", tuple(hi))

    def select(self, vertices) -> np.ndarray:
        v = np.asarray(vertices, float)
        return np.flatnonzero(np.all((v >= self.lower) & (v <= self.upper), axis=1))


def pin_indices(mesh: Mesh, pinned) -> np.ndarray:
    """The sorted particle indices ``pinned`` names on ``mesh``: None or () for none, a
    sequence of vertex indices, the name of one of the file's vertex sets
    (``mesh.groups``), or a :class:`PinBox`.  A MeshError says what is out of range, which
    sets the file has, or that a box holds no vertex."""
    where = mesh.label()
    if pinned is None or (not isinstance(pinned, (str, PinBox)) and np.size(pinned) == 0):
        return np.zeros(0, np.intp)
    if isinstance(pinned, PinBox):
        idx = pinned.select(mesh.vertices)
        if idx.size == 0:
            lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
            raise MeshError(f"{where}: the pin box {pinned.lower}..{pinned.upper} holds no "
                            f"vertex; the mesh spans {tuple(lo.round(4))}..{tuple(hi.round(4))}")
        return idx
    if isinstance(pinned, str):
        if pinned not in mesh.groups:
            have = ", ".join(sorted(mesh.groups)) or "none (OBJ has no vertex sets: give indices)"
            raise MeshError(f"{where}: no vertex set named {pinned!r}; the file's sets: {have}")
        idx = np.asarray(mesh.groups[pinned], np.intp)
        if idx.size == 0:
            raise MeshError(f"{where}: the vertex set {pinned!r} is empty")
        return np.unique(idx)
    idx = np.asarray(pinned).ravel()
    if idx.dtype.kind not in "iu" and not (idx.dtype.kind == "f" and np.all(idx == idx.round())):
        raise MeshError(f"pinned vertices must be whole indices, got {list(pinned)}")
    idx = idx.astype(np.intp)
    bad = idx[(idx < 0) | (idx >= mesh.n)]
    if bad.size:
        raise MeshError(f"{where}: pinned vertex {int(bad[0])} is out of range: the mesh has "
                        f"{mesh.n} vertices, 0..{mesh.n - 1}")
    return np.unique(idx)
