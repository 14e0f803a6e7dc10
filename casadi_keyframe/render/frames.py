"""What every picture shares: which frames to draw, their titles, and writing PNGs and GIFs.

Files are written to a temporary name moved into place when complete, so an interrupted
drawing leaves no half-written picture.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.animation import PillowWriter

from ..interrupts import check
from ..saved import atomic_path


def keyframes(problem) -> list[int]:
    """Sorted distinct frames at which the problem's state terms are active."""
    return sorted({int(t.frame) for t in problem.objective_terms.state_terms})


def select_frames(steps: int, required=(), max_frames: int = 150) -> list[int]:
    """Frames ``0..steps`` to show: all if few, else ~``max_frames + 1`` evenly spaced.

    Frame 0, the last frame and every ``required`` frame are always included.
    """
    if steps <= max_frames:
        return list(range(steps + 1))
    must = {0, steps} | {int(f) for f in required if 0 <= f <= steps}
    grid = set(np.round(np.linspace(0, steps, max(max_frames, 1) + 1)).astype(int).tolist())
    for f in sorted(must - grid):  # swap the nearest free grid frame for each missing one
        free = grid - must
        if free:
            grid.remove(min(free, key=lambda g: abs(g - f)))
        grid.add(f)
    return sorted(grid)


def snapshot_frames(problem, trajectory, frames=None) -> list[int]:
    """Frames of a snapshot: ``frames``, by default the first, each keyframe and the last
    (every keyframe gets its panel, however many there are)."""
    frames = sorted({0, trajectory.steps, *keyframes(problem)} if frames is None
                    else {int(f) for f in frames})
    if not frames or frames[0] < 0 or frames[-1] > trajectory.steps:
        raise ValueError(f"snapshot frames must be in 0..{trajectory.steps}, got {frames}")
    return frames


def grid_shape(count: int, widest: int = 4) -> tuple[int, int]:
    """``(rows, columns)`` of a grid of ``count`` panels, at most ``widest`` columns: one
    row up to three, then as square as it goes."""
    cols = count if count <= 3 else min(widest, int(np.ceil(np.sqrt(count))))
    return -(-count // cols), cols


def frame_title(name: str, n: int, traj, full: bool = True) -> str:
    """``"name - frame n / steps  t = ...s"`` (without the name if not ``full``)."""
    txt = f"frame {n} / {traj.steps}  t = {n * traj.dt:.2f}s"
    return f"{name} \u2014 {txt}" if full else txt


def mass_centers(masses, positions) -> np.ndarray:
    """The centre of mass of each frame of ``positions`` ``(frames, particles, dim)``."""
    w = np.asarray(masses, dtype=float)
    return np.einsum("i,nij->nj", w / w.sum(), np.asarray(positions))


def write_gif(fig, draw, frames, path: Path, fps: int, dpi: int = 80) -> None:
    """Grab ``fig`` after ``draw(n)`` for each of ``frames`` into a GIF at ``path``.

    Written whole or not at all: an interrupted animation leaves no truncated GIF (and the
    frames grabbed so far are dropped, not encoded)."""
    writer = PillowWriter(fps=fps)
    with atomic_path(path) as tmp, matplotlib.rc_context({"savefig.bbox": None}):
        writer.setup(fig, str(tmp), dpi=dpi)
        for n in frames:
            check()
            draw(n)
            writer.grab_frame()
        writer.finish()


def save_figure(fig, path, **kwargs) -> Path:
    """``fig.savefig`` through a temporary file moved into place (see :func:`.io.atomic_path`)."""
    check()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return Path(path)
