"""Warm starts for the cape blend (fig. 6): a PD controller that pulls the cape along a
crossfade of the two clips' shapes and lands it on the target state by inverse steps.

From zero forces no optimizer here brings the blend onto its keyframe without tearing the
cape (``problems/cape_blend.py`` says what was tried); from :func:`tracking_guess` it starts
on the keyframe.  :func:`reference_path` is the crossfade, :func:`tracking_forces` the
controller, :func:`landing_path` the last steps' cubic.  :func:`blend_steps` and
:func:`check_attached` check the blend's arguments and states.
"""
from __future__ import annotations

import numpy as np

from ..checks import frame_at
from ..state import State
from ..objectives.paths import smoothstep


def blend_steps(steps, window, dt: float) -> int:
    """The blend's length in steps: ``steps``, or ``window`` s (default 1 s) on the time
    grid; both given, they must agree."""
    if steps is None:
        steps = frame_at(1.0 if window is None else window, dt, "cape_blend: window")
    elif window is not None and frame_at(window, dt, "cape_blend: window") != steps:
        raise ValueError(f"cape_blend: steps = {steps} and window = {window:.6g} s disagree at "
                         f"dt = {dt:.6g} s; give one of them")
    if int(steps) != steps or steps < 2:
        raise ValueError(f"cape_blend: the blend needs a whole number of steps, at least 2 (the "
                         f"tracking guess lands by two steps), got {steps} (window / dt)")
    return int(steps)


def check_attached(model, x, t: float, clock: float, what: str) -> None:
    """The sewn-on particles of state ``x`` must sit on the blend's shoulder line at ``t``
    (they do by construction: the transition starts on the fall's pose and ends on the
    walk's moved by its offset)."""
    (sewn,) = model.attachments
    gap = np.abs(x[sewn.particles] - sewn.positions(t)).max()
    if gap > 1e-6:
        raise AssertionError(
            f"cape_blend: the {what} puts the sewn-on particles {gap:.3g} m off the "
            f"transition's shoulder line at t = {clock:.6g} s; the source clip and the "
            "transition disagree (a different character, offset or time grid?)")


def reference_path(character, motion, x0, walk_clip, steps: int, dt: float) -> np.ndarray:
    """``(steps + 1, n, 3)`` positions that crossfade the cape as the transition crossfades
    the poses: from ``x0`` held in the torso's frame to the walk clip's cape in its torso
    frame (``walk_clip = (trajectory, animation, first frame)``), blended by the transition's
    smoothstep and carried by the transition's torso.  It starts on ``x0`` and ends on the
    (shifted) walk clip's state, positions and velocities (the smoothstep is flat at the
    end); in between it is not a simulation, so no force makes the cape follow it exactly.

    The fall clip's own cape after ``t_a`` is not followed: it topples over the head, and a
    crossfade with it pulls the hem through the head."""
    def torso(t):
        return character.torso_frame(motion.pose(motion.t_a + t))

    o, S = torso(0.0)
    held = (x0 - o) @ S
    traj, animation, first = walk_clip
    out = np.empty((steps + 1,) + x0.shape)
    for n in range(steps + 1):
        o, S = character.torso_frame(animation.pose((first + n) * dt))
        walking = (traj.x[first + n] - o) @ S
        s = smoothstep(n / steps)
        o, S = torso(n * dt)
        out[n] = o + ((1 - s) * held + s * walking) @ S.T
    return out


def tracking_forces(prob, path, end=None, *, frequency: float = 8.0,
                    start_frequency: float | None = None, damping: float = 0.7,
                    landing_steps: int = 2, stops=None) -> np.ndarray:
    """Per-step forces ``(steps, n, 3)`` of a PD controller that pulls every particle of
    ``prob``'s cape along ``path`` (``(steps + 1, n, 3)``) from its start: ``m (a* + kp (x* -
    x) + kd (v* - v) - g) + drag m v*`` with ``kp = (2 pi f)^2``, ``kd = 2 damping sqrt(kp)``,
    f rising linearly from ``start_frequency`` (default: ``frequency``) to ``frequency`` Hz (at
    most ``1 / (8 dt)``: the PD force is explicit in the step), reference velocities and
    accelerations by differences of the path.  Contacts and the cloth's springs still act,
    so the cape yields where the path runs into the body.  With ``end = (x1, v1)`` the last
    ``landing_steps`` instead follow a cubic from the state the controller reached to exactly
    that state (:func:`landing_path`), by inverse steps (the integrator's ``force_for``).
    Two steps is the least that sets positions and velocities, and the best: an inverse step
    also cancels the contact forces along the cubic, so a longer landing costs more, not
    less.  ``stops = {frame: (x, v)}`` lands on more states the same way, each at its frame
    (``end`` is the stop at the last frame).  Run closed-loop through the problem's integrator; replayed open-loop, the forces
    give the same motion.  (Exact inverse dynamics along the whole path does not yield: it cancels the
    contacts and the stretch the path asks for with forces of thousands of g.)"""
    model, integrator, dt, steps = prob.model, prob.integrator, prob.dt, prob.steps
    top = min(frequency, 0.125 / dt)
    low = top if start_frequency is None else min(start_frequency, top)
    kp = (2 * np.pi * np.linspace(low, top, steps)) ** 2
    kd = 2 * damping * np.sqrt(kp)
    v_ref = np.gradient(path, dt, axis=0)
    a_ref = np.gradient(v_ref, dt, axis=0)
    m = model.masses[:, None]
    g = np.asarray(model.params.gravity)
    stops = {**(stops or {}), **({steps: end} if end is not None else {})}
    starts, prev = {}, 0
    for frame in sorted(stops):  # each landing starts after the one before has ended
        starts[max(frame - max(landing_steps, 2), prev)] = frame
        prev = frame
    x, v, work = prob.x0, prob.v0, integrator.init(model)
    forces = np.zeros((steps,) + x.shape)
    land_from, land_to = -1, -1
    for n in range(steps):
        if n in starts:
            land_from, land_to = n, starts[n]
            land = landing_path(x, v, *stops[land_to], land_to - n, dt)
        if land_from <= n < land_to:
            forces[n] = integrator.force_for(model, x, v, (land[n - land_from + 1] - x) / dt,
                                             n, dt, work)
        else:
            forces[n] = m * (a_ref[n] + kp[n] * (path[n] - x) + kd[n] * (v_ref[n] - v) - g
                             + model.params.air_drag * v_ref[n])
        reached, _ = integrator.step(model, State(x, v), forces[n], n, dt, work)
        x, v = reached.x, reached.v
    return forces


def landing_path(x, v, x1, v1, steps: int, dt: float) -> np.ndarray:
    """``(steps + 1, n, 3)`` positions on a cubic in time from ``x`` moving at ``v`` to
    ``x1``, whose last step moves at ``v1`` (``(p_end - p_before) / dt = v1``, the step's own
    velocity), so stepping along it lands on ``(x1, v1)`` exactly."""
    T = steps * dt
    s = T - dt
    # p(t) = x + v t + a t^2 + b t^3 with p(T) = x1 and p(T) - p(T - dt) = dt v1
    M = np.array([[T ** 2, T ** 3], [T ** 2 - s ** 2, T ** 3 - s ** 3]])
    rhs = np.stack([x1 - x - v * T, dt * (v1 - v)])
    a, b = np.tensordot(np.linalg.inv(M), rhs, axes=1)
    t = dt * np.arange(steps + 1)[:, None, None]
    return x + v * t + a * t ** 2 + b * t ** 3


def tracking_guess(prob, path, end, start_frequencies=(8.0, 4.0, 2.0, 0.5)) -> np.ndarray:
    """Controls of ``prob`` from :func:`tracking_forces` along ``path`` landing on ``end``:
    of the gain ramps from ``start_frequencies`` Hz up to 8 Hz, the one with the least
    control cost (each lands on the keyframe).  A tight hold all the way is cheapest over
    short, violent windows; over a second a loose start lets the cape fall down the back by
    itself."""
    free = prob.controls.idx
    candidates = [tracking_forces(prob, path, end, start_frequency=f)[:, free].ravel()
                  for f in start_frequencies]
    return min(candidates, key=lambda u: prob.control_cost(u)[0])
