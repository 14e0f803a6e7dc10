"""Fig. 3's flock: agents that follow an S-shaped path set by centre-of-mass keyframes, the
problem of ``problems/flock_path.py`` and the studies' exact control case."""
from __future__ import annotations

import numpy as np

from ..models import FlockParams
from ..objectives import CenterOfMassKeyframe, Smoothness
from ..problem import ControlProblem
from .flocks import blob, flock_problem


def path_point(s: float) -> np.ndarray:
    """The S-shaped path of fig. 3 at arc parameter s in [0, 1]."""
    return np.array([40.0 * s, 8.0 * np.sin(2 * np.pi * s)])


def flock_path_problem(agents: int = 100, steps: int = 200, dt: float = 0.05, seed: int = 0,
                       dim: int = 2, keyframes: int = 8, weight: float = 10.0,
                       alpha: float = 1e-3, wander: float = 0.3,
                       cutoff: str = "smooth", tolerance: float = 0.15) -> ControlProblem:
    """Fig. 3: a flock that starts in a blob at the head of :func:`path_point`'s S and follows
    it through ``keyframes`` centre-of-mass keyframes evenly spaced in time, each met within
    ``tolerance`` (length units; the path is about 45 long)."""
    rng = np.random.default_rng(seed)
    horizon = steps * dt
    frames = np.linspace(steps / keyframes, steps, keyframes).round().astype(int)
    start = path_point(0.0)
    v_start = (path_point(1e-3) - start) / 1e-3 / horizon
    objective = sum((CenterOfMassKeyframe(int(f), x=_pad(path_point(f / steps), dim),
                                          position_weight=weight, tolerance=tolerance)
                     for f in frames),
                    Smoothness(alpha))
    v0 = np.zeros((agents, dim))
    v0[:, :2] = 0.5 * v_start
    return flock_problem(agents=agents, steps=steps, dt=dt, seed=seed, dim=dim,
                         objective=objective, x0=blob(agents, start, 1.0, dim, rng), v0=v0,
                         params=FlockParams(cutoff=cutoff), wander=wander, name="flock_path")


def _pad(p, dim):
    out = np.zeros(dim)
    out[:2] = p
    return out
