"""Wavefront OBJ: one file per frame (``obj/NAME_0000.obj`` ...), readable by any 3-D tool,
and the rest mesh that goes with a PC2 point cache (:mod:`.pc2`).

Vertices are written in particle order as float32 values with 9 significant digits, so a
reader gets back exactly the float32 positions, and Blender's Mesh Cache modifier finds its
vertices in the order the cache stores them.  Faces (1-based triangles) only for a cloth; a
flock's file holds its agents as vertices alone.  Coordinates are metres, z up.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..interrupts import check
from ..saved import atomic_path


def obj_text(vertices, faces=None, *, comment: str = "") -> str:
    """The OBJ text of ``vertices`` ``(n, 3)`` and ``faces`` ``(m, k)`` (0-based; triangles,
    or quads for a mesh a DCC will meet as quads)."""
    v = np.asarray(vertices, dtype=np.float32)
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append("\n".join(f"v {a:.9g} {b:.9g} {c:.9g}" for a, b, c in v.tolist()))
    if faces is not None and len(faces):
        f = np.asarray(faces, dtype=int) + 1
        lines.append("\n".join("f " + " ".join(map(str, face)) for face in f.tolist()))
    return "\n".join(lines) + "\n"


def write_obj(path, vertices, faces=None, *, comment: str = "") -> Path:
    """Write one OBJ file, whole or not at all."""
    with atomic_path(path) as tmp:
        tmp.write_text(obj_text(vertices, faces, comment=comment))
    return Path(path)


def write_sequence(scene, folder) -> list[Path]:
    """``folder/NAME_0000.obj`` ... one per frame of ``scene``; returns the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    width = max(4, len(str(scene.frames - 1)))
    paths = []
    for n in range(scene.frames):
        check()
        about = f"{scene.name} frame {n} t = {n * scene.dt:.6g} s (metres, z up)"
        paths.append(write_obj(folder / f"{scene.name}_{n:0{width}d}.obj", scene.positions[n],
                               scene.faces, comment=about))
    return paths


def write_frames(scene, folder) -> list[Path]:
    """``folder/obj/NAME_0000.obj`` ... (the :data:`~casadi_keyframe.export.FORMATS` writer)."""
    return write_sequence(scene, Path(folder) / "obj")


def read_obj(path) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (n, 3) float32, faces (m, k) 0-based)`` of an OBJ file's ``v`` and ``f``
    lines (``f 1/1/1 ...`` forms read by their vertex index)."""
    vertices, faces = [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            vertices.append([float(p) for p in parts[1:4]])
        elif parts[0] == "f":
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
    return (np.array(vertices, dtype=np.float32).reshape(-1, 3),
            np.array(faces, dtype=int).reshape(len(faces), -1 if faces else 3))
