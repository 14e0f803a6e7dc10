"""A triangle mesh read from a file: vertices, triangles, named vertex sets, notices."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Mesh:
    """A checked triangle mesh (see :func:`.checks.check_mesh`).

    ``vertices`` ``(n, 3)`` float64 in the file's order and units; ``faces`` ``(m, 3)``
    0-based triangles; ``groups`` named vertex sets (name -> sorted indices) where the format
    has them; ``source`` the file; ``notices`` what the reading changed (quads triangulated),
    one sentence each, for the caller to show.
    """

    vertices: np.ndarray
    faces: np.ndarray
    groups: dict = field(default_factory=dict)
    source: Path | None = None
    notices: tuple = ()

    @property
    def n(self) -> int:
        return len(self.vertices)

    def label(self) -> str:
        """The file's name for messages, or "mesh" for one built in memory."""
        return str(self.source) if self.source is not None else "mesh"

    def same_topology(self, faces) -> bool:
        """Whether ``faces`` are this mesh's triangles, in any order and any rotation of
        each triangle's corners (a mirrored triangle is another topology)."""
        return _canonical(self.faces) == _canonical(np.asarray(faces))


def _canonical(faces: np.ndarray) -> set:
    """Each triangle rotated to start at its smallest index, as a set of tuples."""
    f = np.asarray(faces, dtype=np.intp).reshape(-1, 3)
    shift = np.argmin(f, axis=1)
    rows = np.arange(len(f))[:, None]
    rotated = f[rows, (shift[:, None] + np.arange(3)) % 3]
    return set(map(tuple, rotated.tolist()))
