"""The state of a particle system, a simulated trajectory, and the error of a failed run."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class SimulationError(RuntimeError):
    """A simulation produced NaN/inf or blew up; ``step`` is where it was detected."""

    def __init__(self, message: str, step: int):
        super().__init__(message)
        self.step = step


@dataclass(frozen=True)
class State:
    """Positions ``x`` and velocities ``v`` of every particle, each ``(particles, dim)``.

    Also the type of a state's tangent (a perturbation, :meth:`Integrator.step_jvp`) and
    cotangent (the adjoint ``(a_x, a_v)`` of eq. 5, :meth:`Integrator.step_vjp`).  Frozen: a
    step returns a new state and never writes into the one it was given.
    """

    x: np.ndarray
    v: np.ndarray


@dataclass
class Trajectory:
    """Positions and velocities per frame: ``x[n]``, ``v[n]`` are ``(particles, dim)``.

    Frame 0 is the initial state and frame ``steps`` the last.  ``records[n]`` is what step
    n left for its backward and tangent steps (a flock's neighbour pairs, a cloth step's
    contacts and solver statistics), empty when the run kept none (values only).
    """

    x: np.ndarray
    v: np.ndarray
    dt: float
    records: list = field(default_factory=list, repr=False)

    @property
    def steps(self) -> int:
        return self.x.shape[0] - 1

    @property
    def times(self) -> np.ndarray:
        return self.dt * np.arange(self.steps + 1)

    def state(self, n: int) -> State:
        """Frame ``n`` as a :class:`State` (read-only views into the trajectory)."""
        x, v = self.x[n].view(), self.v[n].view()
        x.flags.writeable = v.flags.writeable = False
        return State(x, v)

    def record(self, n: int):
        """Step n's record; a clear error if the run kept none."""
        if len(self.records) != self.steps:
            raise ValueError("the trajectory kept no per-step records for a backward or "
                             "tangent pass: simulate it with records=True (the default)")
        return self.records[n]


def check_state(x: np.ndarray, v: np.ndarray, step: int, limit: float = 1e8) -> None:
    """Raise :class:`SimulationError` if the state is non-finite or beyond ``limit``."""
    if not (np.isfinite(x).all() and np.isfinite(v).all()):
        raise SimulationError(f"simulation produced NaN/inf at step {step}: reduce dt, "
                              "the force strengths or the control bounds", step)
    big = max(np.abs(x).max(initial=0.0), np.abs(v).max(initial=0.0))
    if big > limit:
        raise SimulationError(f"simulation blew up at step {step} (|state| = {big:.3g}): "
                              "reduce dt, the force strengths or the control bounds", step)
