"""Controls that move the problem's own simulation along planned positions, step by step.

The forces a transcription computes reproduce its positions exactly when ``simulate``
runs them, but a motion that buckles amplifies the last digit: on a sensitive run the plain
replay of the planned forces may leave the plan far behind by the last frame.  Each step's
force is therefore taken again by the integrator's own inverse step
(:meth:`~casadi_keyframe.integrators.LinearizedBackwardEuler.force_for`) from the state the
simulation actually reached, aimed at the plan's next positions: the run lands on the plan
at every frame (to the linear solves' round-off), the step makes every decision as
``simulate`` makes it (particles held by a body, springs taken taut), and ``simulate`` of
the returned controls repeats the same arithmetic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...state import State


@dataclass(frozen=True)
class Replay:
    """Controls along a plan, with how far their run is from it: ``deviation`` the largest
    distance of a particle from its planned position at any frame (m), ``frame`` where."""

    u: np.ndarray
    deviation: float
    frame: int


def replay_controls(problem, planned, check=None) -> Replay:
    """The controls of ``problem`` (per-step forces on every free particle) whose run
    follows the positions ``planned`` ``(steps + 1, n, 3)`` (module docstring);
    ``check()`` is called between steps (a signal stops the replay by raising)."""
    integrator, model, dt = problem.integrator, problem.model, problem.dt
    work = integrator.init(model)
    x, v = problem.x0.copy(), problem.v0.copy()
    forces = np.zeros((problem.steps, model.n, model.dim))
    pushed = np.zeros(model.n, bool)
    pushed[problem.controls.idx] = True
    worst, at = 0.0, 0
    for n in range(problem.steps):
        if check is not None:
            check()
        target = (planned[n + 1] - x) / dt
        total = integrator.force_for(model, x, v, target, n, dt, work)
        forces[n][pushed] = (total - problem.external[n])[pushed]
        end, _ = integrator.step(model, State(x, v), problem.external[n] + forces[n], n, dt,
                                 work)
        x, v = end.x, end.v
        off = float(np.max(np.linalg.norm(x - planned[n + 1], axis=1)))
        if off > worst:
            worst, at = off, n + 1
    u = forces[:, problem.controls.idx].ravel()
    return Replay(u, worst, at)
