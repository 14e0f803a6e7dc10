"""PC2 point caches, the format of Blender's Mesh Cache modifier (and 3ds Max's Point Cache).

A little-endian header, ``b"POINTCACHE2\\0"``, int32 version 1, int32 number of points,
float32 start frame, float32 sample rate (frames per sample), int32 number of samples, then
float32 ``x y z`` per point per sample.  One sample per frame from frame 0: the scene's frame
rate is ``1 / dt``.  The rest mesh beside it (``NAME_rest.obj``, frame 0) has the same
vertices in the same order, which is what the modifier needs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..meshes.point_cache import HEADER, MAGIC, read_pc2
from ..saved import atomic_path
from .obj import write_obj

__all__ = ["MAGIC", "read_pc2", "write_cache", "write_pc2"]


def write_pc2(path, positions, *, start: float = 0.0, rate: float = 1.0) -> Path:
    """Write ``positions`` ``(samples, points, 3)`` as a PC2 file, whole or not at all."""
    pos = np.ascontiguousarray(positions, dtype="<f4")
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise ValueError(f"a point cache holds (samples, points, 3) positions, got {pos.shape}")
    samples, points, _ = pos.shape
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(HEADER.pack(MAGIC, 1, points, float(start), float(rate), samples))
        f.write(pos.tobytes())
    return Path(path)


def write_cache(scene, folder) -> list[Path]:
    """``folder/NAME.pc2`` (every frame) and ``folder/NAME_rest.obj`` (frame 0)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rest = write_obj(folder / f"{scene.name}_rest.obj", scene.positions[0], scene.faces,
                     comment=f"{scene.name} rest mesh for {scene.name}.pc2 (metres, z up; "
                             f"{1 / scene.dt:.6g} frames per second)")
    return [write_pc2(folder / f"{scene.name}.pc2", scene.positions), rest]
