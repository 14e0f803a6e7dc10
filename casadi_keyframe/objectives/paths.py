"""Paths through the keyframes' targets, for starts and guesses that need no controller:
the quintic :func:`smoothstep` and :func:`keyframe_path`, which rests at each target at its
frame.  Scenes' tracking guesses and the search in positions' blend start share them."""
from __future__ import annotations

import numpy as np


def smoothstep(u):
    """Quintic 0 -> 1 on [0, 1], clamped outside; first and second derivatives vanish at
    both ends, so a blend through it keeps C^2 poses C^2."""
    u = np.clip(u, 0.0, 1.0)
    return u ** 3 * (10 - 15 * u + 6 * u ** 2)


def keyframe_path(x0, terms, steps: int, aims=None) -> np.ndarray:
    """``(steps + 1, n, 3)`` positions from ``x0`` through each keyframe's target at its
    frame (or through ``aims``, one position array per term), smoothstep between them, so
    the path rests at each; held after the last."""
    aims = [t.position_target for t in terms] if aims is None else aims
    stops = [(0, x0)] + [(t.frame, a) for t, a in zip(terms, aims)]
    path = np.empty((steps + 1,) + x0.shape)
    for (f0, a), (f1, b) in zip(stops, stops[1:]):
        s = smoothstep((np.arange(f0, f1 + 1) - f0) / max(f1 - f0, 1))
        path[f0:f1 + 1] = a + s[:, None, None] * (b - a)
    path[stops[-1][0]:] = stops[-1][1]
    return path
