"""Helpers that problem files share to set up a flock problem in a few lines."""
from __future__ import annotations

import numpy as np

from ..controls import StepForces
from ..integrators import SymplecticEuler
from ..models import FlockModel, FlockParams, wander_forces
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
                  controls=None, name: str, view=None, jit=None) -> ControlProblem:
    """A flock control problem with stored wander forces and per-step force controls."""
    if not (isinstance(agents, (int, np.integer)) and agents >= 1):
        raise ValueError(f"agents must be a positive integer, got {agents!r}")
    model = FlockModel(np.ones(agents) if masses is None else masses, dim,
                       params or FlockParams(), jit=jit)
    ext = wander_forces(steps, agents, dim, strength=wander, seed=seed + 1)
    return ControlProblem(model=model, integrator=SymplecticEuler(), x0=x0, v0=v0, steps=steps,
                          dt=dt, controls=controls or StepForces(), objective=objective,
                          external=ext, name=name, view=view)
