r"""The one forward loop and the one backward loop; integrators only step.

Forward: ``s_{n+1} = S_n(s_n, e_n)`` for n = 0 .. N-1 (:func:`simulate`), optionally carrying
a tangent along (:func:`simulate` with ``tangent=``: forward sensitivities in the same pass;
:func:`tangent` carries tangents along a run already recorded).

Backward, eq. (5) of the paper: with ``s_n = (x_n, v_n)`` and ``a_n = dphi/ds_n`` (total),

    a_N = dphi/ds_N,    a_n = (dS_n/ds_n)^T a_{n+1} + dphi/ds_n,    dphi/de_n = (dS_n/de_n)^T a_{n+1}

(:func:`backward`); the product with the transposed step Jacobians is the integrator's
backward step, chosen by the gradient strategy (exact or the paper's swapped one).

Every step of each loop is a safe point (:func:`~casadi_keyframe.interrupts.check`: a
signal or the time limit stops a long run there) and counts as progress
(:mod:`~casadi_keyframe.progress`).
"""
from __future__ import annotations

import numpy as np

from . import progress
from .interrupts import check
from .state import State, Trajectory


def simulate(integrator, model, x0, v0, external, dt: float, *, records: bool = True,
             tangent=None):
    """Run ``len(external)`` steps from ``(x0, v0)``; ``external`` is ``(steps, n, dim)``.

    ``records=False`` keeps no per-step record (values only: on a large flock the records are
    most of the memory).  ``tangent=(dx0, dv0, d_external)`` also carries a tangent through
    every step (the integrator's ``step_jvp``) and returns ``(trajectory, dx, dv)``, the
    tangent per frame, ``(steps + 1, n, dim)`` each.
    """
    steps = external.shape[0]
    x = np.empty((steps + 1,) + np.shape(x0))
    v = np.empty_like(x)
    x[0], v[0] = x0, v0
    traj = Trajectory(x, v, dt)
    work = integrator.init(model)
    work.keep = records
    if tangent is not None:
        dx, dv = np.empty_like(x), np.empty_like(x)
        (dx[0], dv[0]), d_external = tangent[:2], tangent[2]
        tangent_work = integrator.init(model)
    with progress.task("simulating", steps, "steps"):
        for n in range(steps):
            check()
            start = traj.state(n)
            end, record = integrator.step(model, start, external[n], n, dt, work)
            x[n + 1], v[n + 1] = end.x, end.v
            if records:
                traj.records.append(record)
            if tangent is not None:
                out = integrator.step_jvp(model, start, end, record, n, dt,
                                          State(dx[n], dv[n]), d_external[n], tangent_work)
                dx[n + 1], dv[n + 1] = out.x, out.v
            progress.advance()
    return traj if tangent is None else (traj, dx, dv)


def tangent(integrator, model, traj: Trajectory, dx0, dv0, d_external, *, start: int = 0):
    """The tangent of a recorded run: ``(dx0, dv0)`` at frame ``start`` and ``d_external``
    ``(steps, n, dim)`` carried through every later step's ``step_jvp`` on ``traj``'s
    records, without stepping again (many tangents of one run); ``(dx, dv)`` per frame, zero
    before ``start`` (a change that begins there)."""
    if not (isinstance(start, (int, np.integer)) and 0 <= start <= traj.steps):
        raise ValueError(f"tangent: start must be a frame in 0..{traj.steps}, got {start!r}")
    dx, dv = np.zeros_like(traj.x), np.zeros_like(traj.v)
    dx[start], dv[start] = dx0, dv0
    work = integrator.init(model)
    with progress.task("tangent pass", traj.steps - start, "steps"):
        for n in range(start, traj.steps):
            check()
            out = integrator.step_jvp(model, traj.state(n), traj.state(n + 1), traj.record(n),
                                      n, traj.dt, State(dx[n], dv[n]), d_external[n], work)
            dx[n + 1], dv[n + 1] = out.x, out.v
            progress.advance()
    return dx, dv


def backward(integrator, model, traj: Trajectory, gx, gv, *, step_vjp=None, stop: int = 0,
             watch=None):
    """Eq. (5): the frame gradients ``gx, gv`` ``(steps + 1, n, dim)`` pulled back to
    ``(dphi/d external (steps, n, dim), dphi/ds_0 as a State)``.

    ``step_vjp`` is the backward step (default: the integrator's exact one).  ``stop > 0``
    ends the pass at frame ``stop``: the external forces of steps ``stop ..`` get their
    gradients, earlier ones zero, and the State returned is ``dphi/ds_stop`` without the
    frames before it (``gx, gv`` there are not read).  ``watch`` (a
    :class:`~casadi_keyframe.health.BackwardWatch`) sees the cotangent after every backward
    step, without and with the frame's own gradient added; it may stop the pass by raising.
    """
    step_vjp = integrator.step_vjp if step_vjp is None else step_vjp
    steps, dt = traj.steps, traj.dt
    work = integrator.init(model)
    work.records = traj.records
    if not (isinstance(stop, (int, np.integer)) and 0 <= stop <= steps):
        raise ValueError(f"backward: stop must be a frame in 0..{steps}, got {stop!r}")
    g_external = np.zeros((steps,) + traj.x.shape[1:])
    a = State(gx[steps], gv[steps])
    if watch is not None:
        watch.start(gx, gv)
    with progress.task("backward pass", steps - stop, "steps"):
        for n in range(steps - 1, stop - 1, -1):
            check()
            pulled, g_external[n] = step_vjp(model, traj.state(n), traj.state(n + 1),
                                             traj.record(n), n, dt, a, work)
            a = State(pulled.x + gx[n], pulled.v + gv[n])
            if watch is not None:
                watch.step(n, pulled, a)
            progress.advance()
    return g_external, a
