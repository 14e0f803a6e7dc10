"""Where multiple shooting cuts the horizon when its segments are placed by the measured
backward growth (``ShootingOptions(place="growth")``).

A perturbation of a buckling cloth grows by orders of magnitude over a second, unevenly: a
search over one segment sees the growth across it, so equal segments in time leave one
segment with most of it.  :func:`step_growth` measures each step's growth on the run the
shooting starts from: a fixed random end cotangent pulled back through the run's own steps
(the exact backward step, as the health watch does, in its norm ``|(dt a_x, a_v)|``), the
ratio of its size after and before each step.  :func:`growth_spans` cuts the horizon so
that each segment carries an equal share of the total log growth (steps that shrink it
counting as none).
"""
from __future__ import annotations

import math

import numpy as np

from ...simulate import backward


class _StepGrowth:
    """A watch for :func:`~casadi_keyframe.simulate.backward`: each step's growth ratio."""

    def __init__(self, dt: float, steps: int):
        self.dt2, self.ratios, self.previous = dt * dt, np.ones(steps), 0.0

    def _norm(self, s) -> float:
        return math.sqrt(self.dt2 * float(np.vdot(s.x, s.x)) + float(np.vdot(s.v, s.v)))

    def start(self, gx, gv) -> None:
        self.previous = math.sqrt(self.dt2 * float(np.vdot(gx[-1], gx[-1]))
                                  + float(np.vdot(gv[-1], gv[-1])))

    def step(self, n: int, pulled, total) -> None:
        size = self._norm(pulled)
        if self.previous > 0 and math.isfinite(size):
            self.ratios[n] = size / self.previous
        self.previous = self._norm(total)


def step_growth(problem, u, seed: int = 0) -> np.ndarray:
    """Each step's growth ratio of a random end cotangent pulled back along the run of the
    controls ``u`` (``(steps,)``; the free components only, the run's own records)."""
    traj = problem.simulate(u)
    try:
        free = problem.model.free_mask().reshape(traj.x.shape[1:])
        rng = np.random.default_rng(seed)
        gx, gv = np.zeros_like(traj.x), np.zeros_like(traj.v)
        gx[-1] = free * rng.standard_normal(free.shape) / problem.dt
        gv[-1] = free * rng.standard_normal(free.shape)
        watch = _StepGrowth(problem.dt, problem.steps)
        backward(problem.integrator, problem.model, traj, gx, gv, watch=watch)
    finally:
        problem.integrator.release(traj)
    return watch.ratios


def growth_spans(ratios, segments: int) -> list[tuple[int, int]]:
    """``segments`` spans ``(first, last)`` of whole steps, each carrying an equal share of
    the steps' total log growth (``ratios`` of :func:`step_growth`; below 1 counts as 1),
    every segment at least one step long."""
    steps = len(ratios)
    if not 1 <= segments <= steps:
        raise ValueError(f"{segments} shooting segments do not fit in {steps} steps")
    weight = np.log(np.maximum(np.asarray(ratios, dtype=float), 1.0)) + 1e-6  # ties: time
    before = np.concatenate([[0.0], np.cumsum(weight)])  # log growth of steps 0..n-1
    cuts, last = [0], 0
    for j in range(1, segments):
        frame = int(np.argmin(np.abs(before - j * before[-1] / segments)))
        frame = min(max(frame, last + 1), steps - (segments - j))
        cuts.append(frame)
        last = frame
    cuts.append(steps)
    return list(zip(cuts[:-1], cuts[1:]))
