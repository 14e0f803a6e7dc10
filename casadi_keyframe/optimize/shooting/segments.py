"""The horizon cut into segments, each simulated from its own start state: what multiple
shooting (:mod:`.form`) evaluates, in this process or in workers (:mod:`.workers`).

A segment runs the library's own steps through the public loops
(:func:`~casadi_keyframe.simulate.simulate` and :func:`~casadi_keyframe.simulate.backward`)
with the step numbers shifted to where it starts
(:class:`~...integrators.shifted.Shifted`), so forces, colliders and attachments see the
right time; its forward pass keeps the step records (and the factorisations the integrator
keeps in them) for its backward pass, which reuses them, so one evaluation costs one
forward and one backward sweep per segment.

A step may carry decisions to the next beyond the state (held contacts that pulled are
released, springs taken taut stay taut: the integrator's ``carry``).  A segment starts
from what the step before its first one carried (``carried``), so segments that join
without a defect are the single run exactly; :func:`same_carry` says whether two carries
decide alike.
"""
from __future__ import annotations

import numpy as np

from ...simulate import backward, simulate
from ...integrators.shifted import Shifted
from ...state import State


def boundaries(steps: int, segments: int) -> list[tuple[int, int]]:
    """``[(first, last), ...]``: ``segments`` runs of whole steps covering ``0 .. steps``,
    as equal as the steps allow (ValueError naming the limit if there are more segments
    than steps)."""
    if isinstance(segments, bool) or not isinstance(segments, (int, np.integer)) or segments < 1:
        raise ValueError(f"shooting segments must be a whole number >= 1, got {segments!r}")
    if segments > steps:
        raise ValueError(f"{segments} shooting segments do not fit in {steps} steps: give at "
                         f"most {steps}")
    edges = np.linspace(0, steps, segments + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


class SegmentRunner:
    """Forward and backward sweeps of some segments of one model and integrator, keeping
    each forward pass's records for its backward pass (in this process, or in a worker).

    ``spans``: segment index -> ``(first, last)`` frame.
    """

    def __init__(self, model, integrator, dt: float, spans: dict):
        self.model, self.integrator, self.dt = model, integrator, float(dt)
        self.spans = dict(spans)
        self.kept = {}  # segment -> its last forward trajectory (with records)

    def forward(self, k: int, start: State, external, carried=None, tangent=None):
        """Segment ``k`` from ``start`` under ``external`` (``(steps, n, dim)``), its first
        step following one that ``carried`` (None: none): ``(x, v, carry)``, its frames
        ``(steps + 1, n, dim)`` each and what its last step carries on; with
        ``tangent=(dx0, dv0, d_external)`` also the tangent's end state ``(dx, dv)``.
        Raises SimulationError if it fails."""
        first, last = self.spans[k]
        if external.shape[0] != last - first:
            raise ValueError(f"segment {k} has {last - first} steps, got forces for "
                             f"{external.shape[0]}")
        self.drop(k)
        out = simulate(Shifted(self.integrator, first, carried), self.model, start.x, start.v,
                       external, self.dt, tangent=tangent)
        traj = out if tangent is None else out[0]
        self.kept[k] = traj
        carry = self.integrator.carry(self.model, traj.records[-1]) if traj.records else None
        if tangent is None:
            return traj.x, traj.v, carry
        return traj.x, traj.v, carry, (out[1][-1], out[2][-1])

    def backward(self, k: int, gx, gv):
        """The frame cotangents ``gx, gv`` (``(steps + 1, n, dim)``: each frame's objective
        derivative, the end's also what the segment's end is worth) pulled back through the
        last forward pass of segment ``k``: ``(d/d external (steps, n, dim), d/d start)``."""
        traj = self.kept[k]
        g_external, start = backward(Shifted(self.integrator, self.spans[k][0]), self.model,
                                     traj, gx, gv)
        return g_external, start

    def rows(self, k: int, ends) -> list:
        """Segment ``k``'s end-state cotangents ``ends`` (``(x, v)`` pairs, ``(n, dim)``
        each) pulled back one by one through its last forward pass, the frames before the
        end counting nothing: rows of the end state's Jacobian, ``[(d/d external, d/d
        start), ...]``."""
        traj = self.kept[k]
        zeros = np.zeros_like(traj.x)
        out = []
        for ex, ev in ends:
            gx, gv = zeros.copy(), zeros.copy()
            gx[-1], gv[-1] = ex, ev
            out.append(self.backward(k, gx, gv))
        return out

    def drop(self, k: int) -> None:
        """Give back what segment ``k``'s last forward pass kept."""
        traj = self.kept.pop(k, None)
        if traj is not None:
            self.integrator.release(traj)

    def close(self) -> None:
        for k in list(self.kept):
            self.drop(k)


def same_carry(a, b) -> bool:
    """Whether two carries (:meth:`~casadi_keyframe.integrators.base.Integrator.carry`:
    tuples, arrays and None) are the same decisions."""
    if a is None or b is None:
        return a is b
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(same_carry(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        return a.shape == b.shape and bool(np.array_equal(a, b))
    return a == b


class AskedSweeps:
    """The sweeps a pool of workers runs in parallel: a pool gives ``_ask(what, payload)``,
    which hands each worker its segments' part and gathers the answers."""

    def forward(self, items: dict) -> dict:
        """The segments ``items`` names, in parallel, each from the carry it is given."""
        out = self._ask("forward", dict(items))
        return {k: (x, v, items[k][2], carry) for k, (x, v, carry) in out.items()}

    def backward(self, cotangents) -> list:
        return self._ask("backward", list(cotangents))
