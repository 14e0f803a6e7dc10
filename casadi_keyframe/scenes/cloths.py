"""Helpers that cloth problem files share: the problem itself and target shapes of a sheet."""
from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from ..controls import StepForces
from ..integrators import LinearizedBackwardEuler
from ..problem import ControlProblem
from .maths import rotation


def cloth_problem(*, model, steps: int, dt: float, objective, name: str, x0=None, v0=None,
                  controls=None, view=None, solver: str = "auto", guess=None,
                  inputs=(), limits=None) -> ControlProblem:
    """A cloth control problem integrated by linearized backward Euler (rest shape and rest
    velocities by default, per-step force controls on the free particles by default);
    ``inputs``: the files it is built from; ``limits``: its physical limits (default ones)."""
    x0 = model.rest_positions if x0 is None else x0
    v0 = np.zeros_like(x0) if v0 is None else v0
    if controls is None:
        controls = StepForces(agents=np.flatnonzero(model.free_mask()[::3]))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler(solver),
                          x0=x0, v0=v0, steps=steps, dt=dt, controls=controls,
                          objective=objective, name=name, view=view, guess=guess,
                          inputs=inputs, limits=limits)


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


def wave_across(points, amplitude, along: int = 0, out: int = 1) -> np.ndarray:
    """A sheet's rows (``points`` sharing every coordinate but ``along``) each bent into one
    full sine period of ``amplitude`` (per point, the same along a row) in direction ``out``,
    the row's length kept: its particles go at their rest distances along the curve, so the
    row spans less the deeper its wave (a shape cloth can take without stretching)."""
    p = np.array(points, dtype=float)
    amplitude = np.broadcast_to(np.asarray(amplitude, float), (len(p),))
    rest = np.delete(p, along, axis=1).round(12)
    _, row = np.unique(np.c_[rest, amplitude.round(12)], axis=0, return_inverse=True)
    t = np.linspace(0.0, 1.0, 4001)
    for r in np.unique(row):
        members = np.flatnonzero(row.ravel() == r)
        s = p[members, along]
        lo, length, a = s.min(), np.ptp(s), amplitude[members[0]]
        if length == 0 or a == 0:
            continue
        wave = a * np.sin(2 * np.pi * t)

        def arc(span):
            return np.r_[0.0, np.cumsum(np.hypot(np.diff(span * t), np.diff(wave)))]

        span = brentq(lambda w: arc(w)[-1] - length, 1e-9 * length, length)
        at = np.interp(s - lo, arc(span), t)
        p[members, along] = lo + length / 2 + span * (at - 0.5)
        p[members, out] += a * np.sin(2 * np.pi * at)
    return p
