"""A simulated trajectory and the error raised when a simulation fails."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class SimulationError(RuntimeError):
    """A simulation produced NaN/inf or blew up; ``step`` is where it was detected."""

    def __init__(self, message: str, step: int):
        super().__init__(message)
        self.step = step


@dataclass
class Trajectory:
    """Positions and velocities per frame: ``x[n]``, ``v[n]`` are ``(particles, dim)``.

    Frame 0 is the initial state and frame ``steps`` the last; ``tape`` holds whatever the
    integrator needs for its adjoint (neighbour lists, factorizations).
    """

    x: np.ndarray
    v: np.ndarray
    dt: float
    tape: list = field(default_factory=list, repr=False)

    @property
    def steps(self) -> int:
        return self.x.shape[0] - 1

    @property
    def times(self) -> np.ndarray:
        return self.dt * np.arange(self.steps + 1)


def check_state(x: np.ndarray, v: np.ndarray, step: int, limit: float = 1e8) -> None:
    """Raise :class:`SimulationError` if the state is non-finite or beyond ``limit``."""
    if not (np.isfinite(x).all() and np.isfinite(v).all()):
        raise SimulationError(f"simulation produced NaN/inf at step {step}: reduce dt, "
                              "the force strengths or the control bounds", step)
    big = max(np.abs(x).max(initial=0.0), np.abs(v).max(initial=0.0))
    if big > limit:
        raise SimulationError(f"simulation blew up at step {step} (|state| = {big:.3g}): "
                              "reduce dt, the force strengths or the control bounds", step)
