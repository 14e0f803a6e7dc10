"""A hanging sheet as mesh files, and two target shapes it can reach without stretching: a
wave across it and a fold along a horizontal line.  What the mesh_keyframes problem, its
tests and the README's walk-through write to disk to stand for an animator's meshes."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..export.obj import write_obj
from ..models.topology import grid_topology
from .cloths import wave_across


def hanging_sheet(rows: int, cols: int, size: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, quads)`` of a ``size`` x ``size`` sheet in the plane y = 0, row 0 along
    the top (z = 0), vertex ``r * cols + c`` (the layout of ``ClothModel.grid``)."""
    r, c = np.divmod(np.arange(rows * cols), cols)
    vertices = np.stack([c * size / (cols - 1), np.zeros(rows * cols),
                         -r * size / (rows - 1)], axis=1)
    return vertices, grid_topology(rows, cols)[1]


def wave(vertices, depth: float = 0.2) -> np.ndarray:
    """Each row of a hanging sheet bent into one sine period toward +y, ``depth`` times its
    distance below the top row deep, each row's length kept (``cloths.wave_across``)."""
    top = vertices[:, 2].max()
    return wave_across(vertices, depth * (top - vertices[:, 2]), along=0, out=1)


def fold(vertices, at: float = 0.45, radius: float = 0.15, angle: float = 100.0) -> np.ndarray:
    """A hanging sheet folded toward +y below the line ``at`` metres under its top row: the
    cloth rolls around a cylinder of ``radius`` through ``angle`` degrees, then goes on
    straight.  Every vertical line keeps its length along the cloth (the shape is
    developable), so no spring needs to stretch."""
    p = np.array(vertices, dtype=float)
    line = p[:, 2].max() - at
    s = np.maximum(line - p[:, 2], 0.0)  # distance below the fold line, along the cloth
    phi = np.radians(angle)
    arc = np.minimum(s, radius * phi) / radius
    beyond = np.maximum(s - radius * phi, 0.0)
    p[:, 1] += radius * (1 - np.cos(arc)) + beyond * np.sin(phi)
    p[:, 2] = np.where(s > 0, line - radius * np.sin(arc) - beyond * np.cos(phi), p[:, 2])
    return p


def write_sheet_and_targets(folder, rows: int = 30, cols: int = 30, size: float = 1.0) -> dict:
    """``sheet.obj`` (quads, as a DCC writes them), ``wave.obj`` and ``fold.obj`` in
    ``folder``; returns their paths by name."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    vertices, quads = hanging_sheet(rows, cols, size)
    shapes = {"sheet": vertices, "wave": wave(vertices), "fold": fold(vertices, at=0.45 * size,
                                                                     radius=0.15 * size)}
    return {name: write_obj(folder / f"{name}.obj", x, quads,
                            comment=f"{name}: {rows} x {cols} hanging sheet, metres, z up")
            for name, x in shapes.items()}


def carried(vertices, frames: int, shift=(0.5, 0.0, 0.0)) -> np.ndarray:
    """``(frames + 1, v, 3)``: ``vertices`` carried by ``shift`` (m) over ``frames`` frames
    along a smoothstep (at rest at both ends): the time-sampled mesh a ``pin_motion`` reads."""
    s = np.linspace(0.0, 1.0, frames + 1)
    ramp = s * s * (3 - 2 * s)
    return np.asarray(vertices, float)[None] + ramp[:, None, None] * np.asarray(shift, float)


def write_carried_sheet(folder, rows: int = 12, cols: int = 12, frames: int = 60,
                        shift=(0.5, 0.0, 0.0), dt: float = 1 / 60) -> dict:
    """A hanging sheet (``sheet.obj``), its motion carried by ``shift`` over ``frames``
    frames (``carried.pc2`` beside ``carried_rest.obj``, one sample per ``dt``: what
    ``pin_motion`` takes) and the wave carried as far (``wave_carried.obj``, whose top row is
    where the motion leaves the sheet's); returns their paths by name."""
    from ..export.pc2 import write_pc2

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    vertices, quads = hanging_sheet(rows, cols)
    motion = carried(vertices, frames, shift)
    note = f"{rows} x {cols} hanging sheet, metres, z up"
    out = {"sheet": write_obj(folder / "sheet.obj", vertices, quads, comment=f"sheet: {note}"),
           "rest": write_obj(folder / "carried_rest.obj", vertices, quads,
                             comment=f"rest mesh for carried.pc2 ({1 / dt:.6g} frames per "
                                     "second)"),
           "wave": write_obj(folder / "wave_carried.obj", wave(vertices) + motion[-1] - vertices,
                             quads, comment=f"the wave carried by {tuple(shift)} m: {note}")}
    out["motion"] = write_pc2(folder / "carried.pc2", motion)
    return out
