"""What every picture shares: which frames to draw, their titles, and writing PNGs and GIFs.

Files are written to a temporary name moved into place when complete, so an interrupted
drawing leaves no half-written picture.  An animation says how far it is
(:mod:`~casadi_keyframe.progress`) and may be given a time to draw in: past it, the frames
left are thinned (every one asked to be kept, and the last, stay).
"""
from __future__ import annotations

import time
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.animation import PillowWriter

from .. import progress
from ..interrupts import check
from ..saved import atomic_path

ENCODING = 0.8  # the share of a GIF's time limit its frames may take (the rest: encoding)


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


def write_gif(fig, draw, frames, path: Path, fps: int, dpi: int = 80, *,
              limit: float | None = None, keep=()) -> int:
    """Grab ``fig`` after ``draw(n)`` for each of ``frames`` into a GIF at ``path``; the
    frames drawn, a count.

    Written whole or not at all: an interrupted animation leaves no truncated GIF (and the
    frames grabbed so far are dropped, not encoded).  With ``limit`` (seconds), once the
    frames drawn so far say the rest would not fit in it, the rest are thinned to what
    fits, keeping those of ``keep`` and the last; a line says so."""
    writer = PillowWriter(fps=fps)
    frames, planned, began = list(frames), len(frames), time.monotonic()
    with atomic_path(path) as tmp, matplotlib.rc_context({"savefig.bbox": None}), \
            progress.task(f"drawing {Path(path).name}", len(frames), "frames") as task:
        writer.setup(fig, str(tmp), dpi=dpi)
        i = 0
        while i < len(frames):
            check()
            draw(frames[i])
            writer.grab_frame()
            i += 1
            progress.advance()
            if limit is not None and i >= 3:
                frames = _fitted(frames, i, time.monotonic() - began, ENCODING * limit, keep)
                task.total = len(frames)
        writer.finish()
    if len(frames) < planned:
        progress.say(f"  {Path(path).name}: {len(frames)} of {planned} frames drawn, to fit "
                     f"its {limit:g} s (--draw-limit)", stage=True)
    return len(frames)


def _fitted(frames: list, drawn: int, spent: float, limit: float, keep) -> list:
    """``frames`` with those after the first ``drawn`` thinned to what fits in what is left
    of ``limit`` seconds at the pace so far (``spent`` seconds for ``drawn``)."""
    rest = frames[drawn:]
    room = int(max(limit - spent, 0.0) / (spent / drawn))
    if len(rest) <= room:
        return frames
    wanted = [j for j, f in enumerate(rest) if f in set(keep)]
    chosen = select_frames(len(rest) - 1, wanted, max(room - 1, 0)) if room > 1 else [
        len(rest) - 1]
    return frames[:drawn] + [rest[j] for j in chosen]


def save_figure(fig, path, **kwargs) -> Path:
    """``fig.savefig`` through a temporary file moved into place (see :func:`.io.atomic_path`)."""
    check()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return Path(path)
