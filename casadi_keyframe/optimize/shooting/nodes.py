"""Where multiple shooting's node states start (:data:`INITS`).

* ``"passive"``: the passive run (zero controls) at each node's frame;
* ``"guess"``: the run of the stage's starting controls (the problem's guess, or the
  controls an earlier stage carried over): consistent nodes, no defect;
* ``"target"``: the state the next full keyframe asks for (every particle's position, and
  its velocity where the keyframe gives one);
* ``"blend"``: from the passive run (or the previous full keyframe's target) towards that
  target, linearly in time;
* a function ``path(problem) -> (steps + 1, n, dim)`` positions: a problem's own guess of
  the states it passes through, velocities by central differences of the path.

Pinned and attached particles keep their prescribed motion (from the reference run) in
every case; ``target`` and ``blend`` need a StateKeyframe over every particle with a
position target, after the node.
"""
from __future__ import annotations

import numpy as np

from ...objectives import StateKeyframe
from ...state import State

INITS = ("passive", "guess", "target", "blend")


def reference_run(problem, u0):
    """The run of the starting controls ``u0``: the nodes' prescribed components (and the
    ``guess`` nodes)."""
    return problem.simulate(u0, records=False)


def initial_nodes(problem, shooting, init: str, reference) -> list:
    """The starting node States of ``shooting`` (see the module)."""
    if init == "guess":
        return shooting.nodes_of(reference)
    if callable(init):
        return _on_path(problem, shooting, init(problem))
    passive = shooting.nodes_of(problem.simulate(records=False))
    if init == "passive":
        return passive
    keys = _full_keyframes(problem)
    if not keys:
        raise ValueError(f"{problem.name}: shooting init {init!r} needs a StateKeyframe with a "
                         "position target for every particle; use init 'passive' or 'guess'")
    nodes = []
    for (a, _), s, ref in zip(shooting.spans[1:], passive, shooting.reference):
        after = [k for k in keys if k[0] >= a]
        before = [k for k in keys if k[0] < a]
        if not after:
            x, v = s.x, s.v
        elif init == "target":
            x, v = _target(after[0], s)
        else:
            f, p = after[0][0], (before[-1][0] if before else 0)
            start = _target(before[-1], s) if before else (s.x, s.v)
            end = _target(after[0], s)
            tau = (a - p) / (f - p)
            x, v = ((1 - tau) * q0 + tau * q1 for q0, q1 in zip(start, end))
        x, v = np.where(shooting.free, x, ref.x), np.where(shooting.free, v, ref.v)
        nodes.append(State(np.array(x), np.array(v)))
    return nodes


def _on_path(problem, shooting, path) -> list:
    """Nodes on the positions ``path`` (``(steps + 1, n, dim)``), velocities by central
    differences, prescribed components from the reference run."""
    path = np.asarray(path, dtype=float)
    if path.shape != (problem.steps + 1,) + shooting.free.shape:
        raise ValueError(f"{problem.name}: a shooting init path must give "
                         f"{(problem.steps + 1,) + shooting.free.shape} positions, got "
                         f"{path.shape}")
    nodes = []
    for (a, _), ref in zip(shooting.spans[1:], shooting.reference):
        v = (path[a + 1] - path[a - 1]) / (2 * problem.dt)
        nodes.append(State(np.where(shooting.free, path[a], ref.x),
                           np.where(shooting.free, v, ref.v)))
    return nodes


def _full_keyframes(problem) -> list:
    """``(frame, positions, velocities or None)`` of the StateKeyframes over every particle
    with a position target, by frame."""
    n = problem.model.n
    out = []
    for t in problem.objective_terms.state_terms:
        if (isinstance(t, StateKeyframe) and t.position_target is not None
                and np.unique(t.particles).size == n):
            x = np.empty((n, problem.model.dim))
            x[t.particles] = t.position_target
            v = None
            if t.velocity_target is not None:
                v = np.empty_like(x)
                v[t.particles] = t.velocity_target
            out.append((t.frame, x, v))
    return sorted(out, key=lambda k: k[0])


def _target(key, passive: State):
    """A keyframe's positions and velocities (the passive velocities where it gives none)."""
    _, x, v = key
    return x, (passive.v if v is None else v)
