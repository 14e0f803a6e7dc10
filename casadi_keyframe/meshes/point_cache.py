"""Reading PC2 point caches (the format :mod:`~..export.pc2` writes and Blender's Mesh Cache
modifier plays): a little-endian header, ``b"POINTCACHE2\\0"``, int32 version 1, int32 number
of points, float32 start frame, float32 sample rate, int32 number of samples, then float32
``x y z`` per point per sample."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

MAGIC = b"POINTCACHE2\0"
HEADER = struct.Struct("<12siiffi")


def read_pc2(path) -> tuple[np.ndarray, float, float]:
    """``(positions (samples, points, 3) float32, start, rate)`` of a PC2 file."""
    data = Path(path).read_bytes()
    if len(data) < HEADER.size:
        raise ValueError(f"{path} is too short for a PC2 header")
    magic, version, points, start, rate, samples = HEADER.unpack_from(data)
    if magic != MAGIC or version != 1:
        raise ValueError(f"{path} is not a PC2 version 1 file (header {magic!r}, {version})")
    expected = HEADER.size + 12 * points * samples
    if len(data) != expected:
        raise ValueError(f"{path} holds {len(data)} bytes, its header promises {expected}")
    pos = np.frombuffer(data, dtype="<f4", offset=HEADER.size).reshape(samples, points, 3)
    return pos, start, rate
