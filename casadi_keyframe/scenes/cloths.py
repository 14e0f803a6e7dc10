"""Helpers that cloth problem files share: the problem itself and target shapes of a sheet."""
from __future__ import annotations

import numpy as np

from ..controls import StepForces
from ..integrators import LinearizedBackwardEuler
from ..problem import ControlProblem
from .maths import rotation


def cloth_problem(*, model, steps: int, dt: float, objective, name: str, x0=None, v0=None,
                  controls=None, view=None, solver: str = "auto", guess=None) -> ControlProblem:
    """A cloth control problem integrated by linearized backward Euler (rest shape and rest
    velocities by default, per-step force controls on the free particles by default)."""
    x0 = model.rest_positions if x0 is None else x0
    v0 = np.zeros_like(x0) if v0 is None else v0
    if controls is None:
        controls = StepForces(agents=np.flatnonzero(model.free_mask()[::3]))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(solver),
                          x0=x0, v0=v0, steps=steps, dt=dt, controls=controls,
                          objective=objective, name=name, view=view, guess=guess)


def weight_support(model, controls, steps: int) -> np.ndarray:
    """Per-step forces that cancel gravity on the controlled particles: a starting guess that
    lifts a sheet off the ground, where resting contact leaves almost no gradient."""
    support = -model.masses[controls.idx, None] * np.asarray(model.params.gravity)
    return np.tile(support, (steps, 1, 1)).ravel()


def rotate_about(points, pivot, axis, angle: float) -> np.ndarray:
    """``points`` (n, 3) rotated about the line through ``pivot`` along ``axis``."""
    pivot = np.asarray(pivot, float)
    return (np.asarray(points) - pivot) @ rotation(axis, angle).T + pivot


def bend_into_arch(points, axis: int = 0, up: int = 2, lift: float = 0.0) -> np.ndarray:
    """A flat sheet (``points`` spread along coordinate ``axis``, flat in ``up``) rolled into a
    half cylinder of the same arc length, ends kept on the original level, raised ``lift``."""
    p = np.array(points, dtype=float)
    s = p[:, axis] - p[:, axis].min()
    length = s.max()
    radius = length / np.pi
    theta = np.pi * s / length
    center = p[:, axis].min() + length / 2
    p[:, axis] = center - radius * np.cos(theta)
    p[:, up] = p[:, up] + radius * np.sin(theta) + lift
    return p
