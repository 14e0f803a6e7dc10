"""A mesh with its per-frame vertices: what a moving body is read from.

:func:`read_animated` reads an OBJ or PLY (still), a USD file (still, or animated by
time-sampled points or a time-sampled transform of its mesh) or a PC2 point cache with its
rest mesh (``NAME.pc2`` beside ``NAME_rest.obj``, as :mod:`~..export.pc2` and Blender's Mesh
Cache write them).  Times count from the first frame: a USD file's first time sample, a
PC2 file's first sample, is t = 0.  The mesh is checked as a body
(:func:`~.checks.check_body`: faces wound alike and out, an open one noted).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checks import MeshError, check_body
from .mesh import Mesh
from .point_cache import read_pc2
from .readers import read_mesh, usd_frames


@dataclass(frozen=True)
class Animated:
    """``mesh`` (its vertices: the first frame's, or the rest shape's for a PC2 cache) and,
    when it moves, ``frames`` ``(k, v, 3)`` at ``times`` ``(k,)`` s (None when still)."""

    mesh: Mesh
    frames: np.ndarray | None = None
    times: np.ndarray | None = None


def read_animated(path, *, rest=None, fps: float | None = None) -> Animated:
    """The mesh in ``path`` and its frames (module docstring); ``rest`` names a PC2
    cache's rest mesh (default ``NAME_rest.obj`` beside it) and ``fps`` its frame rate (a
    PC2 file has none).  A :class:`MeshError` names the file and what to give."""
    path = Path(path)
    if path.suffix.lower() != ".pc2":
        mesh = check_body(read_mesh(path, "body"))
        if path.suffix.lower() not in (".usd", ".usda", ".usdc", ".usdz"):
            return Animated(mesh)
        sampled = usd_frames(path)
        return Animated(mesh) if sampled is None else Animated(mesh, sampled[1], sampled[0])
    rest = path.with_name(f"{path.stem}_rest.obj") if rest is None else Path(rest)
    if not rest.is_file():
        raise MeshError(f"{path}: a PC2 cache holds points only; its faces come from its rest "
                        f"mesh, {rest}, which is missing: put the rest OBJ beside it")
    if fps is None or not fps > 0:
        raise MeshError(f"{path}: a PC2 cache holds no frame rate; give its frames per second")
    mesh = check_body(read_mesh(rest, "body"))
    try:
        frames, _, rate = read_pc2(path)
    except ValueError as err:
        raise MeshError(str(err)) from None
    if frames.shape[1] != mesh.n:
        raise MeshError(f"{path}: {frames.shape[1]} points per frame, but its rest mesh "
                        f"{rest} has {mesh.n} vertices: export them from the same mesh")
    return Animated(mesh, np.asarray(frames, float), np.arange(len(frames)) * rate / fps)
