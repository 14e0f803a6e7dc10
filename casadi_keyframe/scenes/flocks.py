"""Helpers that problem files share to set up a flock problem in a few lines, and fig. 3's
path-following flock (:func:`flock_path_problem`), which the studies use too."""
from __future__ import annotations

import numpy as np

from ..controls import StepForces
from ..integrators import SymplecticEuler
from ..models import FlockModel, FlockParams, wander_forces
from ..objectives import CenterOfMassKeyframe, Smoothness
from ..problem import ControlProblem


def blob(n: int, center, spacing: float, dim: int, rng) -> np.ndarray:
    """``n`` agents scattered in a disc (ball) whose area fits ``spacing`` per agent."""
    radius = spacing * np.sqrt(n) / 2 if dim == 2 else spacing * np.cbrt(n) / 1.6
    pts = rng.standard_normal((n, dim))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    pts *= radius * rng.uniform(0, 1, (n, 1)) ** (1 / dim)
    out = np.zeros((n, dim))
    out[:, :len(center)] = center
    return out + pts


def flock_problem(*, agents: int, steps: int, dt: float, seed: int, dim: int, objective,
                  x0, v0, params: FlockParams | None = None, masses=None, wander: float = 0.3,
                  controls=None, name: str, scene=None, jit=None) -> ControlProblem:
    """A flock control problem with stored wander forces and per-step force controls."""
    if not (isinstance(agents, (int, np.integer)) and agents >= 1):
        raise ValueError(f"agents must be a positive integer, got {agents!r}")
    model = FlockModel(np.ones(agents) if masses is None else masses, dim,
                       params or FlockParams(), jit=jit)
    ext = wander_forces(steps, agents, dim, strength=wander, seed=seed + 1)
    return ControlProblem(model=model, integrator=SymplecticEuler(), x0=x0, v0=v0, steps=steps,
                          dt=dt, controls=controls or StepForces(), objective=objective,
                          external=ext, name=name, scene=scene)


def path_point(s: float) -> np.ndarray:
    """The S-shaped path of fig. 3 at arc parameter s in [0, 1]."""
    return np.array([40.0 * s, 8.0 * np.sin(2 * np.pi * s)])


def flock_path_problem(agents: int = 100, steps: int = 200, dt: float = 0.05, seed: int = 0,
                       dim: int = 2, keyframes: int = 8, weight: float = 10.0,
                       alpha: float = 1e-3, wander: float = 0.3,
                       cutoff: str = "smooth") -> ControlProblem:
    """Fig. 3: a flock that starts in a blob at the head of :func:`path_point`'s S and follows
    it through ``keyframes`` centre-of-mass keyframes evenly spaced in time."""
    rng = np.random.default_rng(seed)
    horizon = steps * dt
    frames = np.linspace(steps / keyframes, steps, keyframes).round().astype(int)
    start = path_point(0.0)
    v_start = (path_point(1e-3) - start) / 1e-3 / horizon
    objective = sum((CenterOfMassKeyframe(int(f), x=_pad(path_point(f / steps), dim),
                                          position_weight=weight) for f in frames),
                    Smoothness(alpha))
    v0 = np.zeros((agents, dim))
    v0[:, :2] = 0.5 * v_start
    return flock_problem(agents=agents, steps=steps, dt=dt, seed=seed, dim=dim,
                         objective=objective, x0=blob(agents, start, 1.0, dim, rng), v0=v0,
                         params=FlockParams(cutoff=cutoff), wander=wander, name="flock_path",
                         scene={"path": np.array([path_point(s) for s in np.linspace(0, 1, 100)])})


def _pad(p, dim):
    out = np.zeros(dim)
    out[:2] = p
    return out
