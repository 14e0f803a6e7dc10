"""The rest start of a search in positions where particles are led along paths (a cape sewn
to a walking character): the start state held still in world space would leave the pins
behind and tear the cloth at its seam, so it is held still relative to its pins instead,
carried frame by frame by the rigid motion that best carries the led particles from where
they start.  With no led particles (pinned ones stay put) it is the start held still."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...geometry import best_rigid_motion

LINE = 1e-6  # led particles whose spread across their main line is below this share of
# its length lie on a line (a shoulder line): the turn about it is left open


def carried_rest(problem) -> np.ndarray:
    """The positions ``(steps + 1, n, 3)``: ``problem.x0`` carried by the led particles'
    rigid motion at every frame (module docstring)."""
    x0, N, dt = problem.x0, problem.steps, problem.dt
    out = np.repeat(x0[None], N + 1, axis=0)
    attachments = getattr(problem.model, "attachments", ())
    if not attachments:
        return out
    start = np.concatenate([x0[a.particles] for a in attachments])
    for k in range(1, N + 1):
        led = np.concatenate([a.positions(k * dt) for a in attachments])
        R, t = carrying_motion(start, led)
        out[k] = x0 @ R.T + t
    return out


def carrying_motion(source, dest) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` carrying the points ``source`` closest to ``dest`` (both ``(k, 3)``):
    Kabsch's, or where the source points lie on a line (or are one point), the least turn
    that carries the line's direction onto the destination's and their centres together."""
    source, dest = np.asarray(source, float), np.asarray(dest, float)
    c0, c1 = source.mean(axis=0), dest.mean(axis=0)
    spread = np.linalg.svd(source - c0, compute_uv=False) if len(source) > 1 else np.zeros(1)
    if len(source) >= 3 and spread[1] > LINE * spread[0]:
        return best_rigid_motion(source, dest)
    if spread[0] == 0.0:  # one point: carried, not turned
        return np.eye(3), c1 - c0
    axis = np.linalg.svd(source - c0, full_matrices=False)[2][0]
    along = (dest - c1).T @ ((source - c0) @ axis)  # the destination's line, same sense
    R = (Rotation.align_vectors([along], [axis])[0].as_matrix()
         if np.linalg.norm(along) > 0 else np.eye(3))
    return R, c1 - R @ c0
