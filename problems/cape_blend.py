"""Fig. 6: a cape blended from a fall into a walk, a boundary-value problem.

Two passive clips of the same cape (:func:`casadi_keyframe.scenes.capes.simulate_clip`): a
stunt double falls 2 m and lands face down (``fall``), an actor walks (``walk``).  The blend
starts from the fall clip's cape at its time ``t_a`` (position AND velocity of every
particle) while the character moves through ``animations.transition(fall, walk, t_a, t_b,
window)``; per-step forces on the free (not sewn-on) particles must bring the cape,
``window`` s later, onto the walk clip's cape at its time ``t_b + window``, positions and
velocities, the positions moved by the transition's horizontal ``offset`` (which lines the
walk up with where the body lands).  Minimal, smooth forces: :class:`Smoothness` with a
temporal term.  ``scene`` refers to the character, the transition (``animation``, on the
fall clip's clock: the blend's frame k is at ``t_a + k dt``) and both clips (``clips[kind] =
(model, trajectory)``, shared, not copies: the fall's frame ``t_a / dt + k`` and the walk's
``t_b / dt + k`` go with the blend's frame k), for drawing the three side by side.

Defaults.  ``t_a = 0.8`` s: the body is landing (its root 11 cm above where it comes to
rest) and the cape, flung up by the fall, streams straight out of its back, the hem about
1 m behind the shoulders in the torso's frame (8 x 6, 13 x 8 and 26 x 16 capes alike).  By
1.1 s it has toppled over the head onto the ground beyond; blends from there (t_a 1.0, 1.5,
2.0 s, 8 x 6) ended with the cape over the head or a shoulder, passive and as L-BFGS-B left
it (rms 0.43-0.51 m off, 72-85 % of the cape's width): the way back behind the body goes
round the head, and a straight pull runs into it.  From 0.8 s the cape can swing down the
back as the body gets up.  ``window = 1.0`` s (or ``steps``) to get up from face down into
the walk: the shorter, the faster the limbs and the cape (the 8 x 6 cape's tracking guess
below needs control accelerations of 32 m/s^2 rms over 1 s, 68 over 0.5 s, 104 over
0.4 s).  ``t_b = 0.6`` s, a little over half a stride: the transition blends poses only, so
the lower legs sweep through the floor while the body turns upright, and this phase keeps
them shallowest (10 cm below z = 0 at worst, other phases down to 23 cm), under the hem.

Weights.  The keyframe term is ``0.5 (position_weight |x - x*|^2 + velocity_weight |v -
v*|^2) / n``: a sum over the n particles, so without the ``/ n`` the same miss would cost 8.7
times more on the 26 x 16 cape than on an 8 x 6 one; with it the term is ``0.5
(position_weight rms_x^2 + velocity_weight rms_v^2)`` at any resolution.  ``position_weight
= 400`` m^-2 puts the passive miss (rms 0.54-0.71 m) at 56-92 and a 1 cm miss at 0.02, so
the keyframe dominates at the start and still pulls at the end; ``velocity_weight = 4``
(s/m)^2 = position_weight (0.1 s)^2: a velocity miss costs as much as the position miss it
makes in 0.1 s, about the cape's swing time.  Forces per particle scale with the particle
mass (mass / n), so ``alpha`` and ``temporal`` are divided by the mean particle mass: the
control cost is ``0.5 alpha int sum m |a|^2 dt + 0.5 temporal int sum m |da/dt|^2 dt`` in
the control accelerations ``a = u / m``, the same at every resolution.  The defaults make it
0.014-0.025 at the tracking guess over 1 s (26 x 16 to 8 x 6), under a thousandth of the
passive miss's cost.

Hitting the keyframe.  From zero forces (the paper's start) L-BFGS-B stalls far from the
walk.  ``benchmarks/cape_blend_strategies.py`` measures what the library offers against it
(8 x 6 cape, 1 s, 100 iterations each; rms position miss over the free particles, passive
0.61 m; the largest spring stretch; the deepest particle in the body; measured with the
cloth's earlier strut-like compression law, before issue 11 gave it the Choi-Ko law's own):

    exact adjoint, L-BFGS-B                    0.385 m   stretch 2.14   8 cm
    swapped adjoint (the paper's)              0.571 m   (its first line search fails)
    IPOPT                                      0.010 m   stretch 3.67   4.9 cm
    continuation from 2 dt                     0.402 m   stretch 1.70   3 cm
    keyframe weight x10 per round, 3 rounds    0.322 m   stretch 2.13   6 cm
    multipliers + weight x10, 3 rounds         0.051 m   stretch 1.91   4.1 cm
    tracking guess (default), then L-BFGS-B    4e-7 m    stretch 1.07   0

So from zero forces IPOPT gets closest, then the augmented Lagrangian
(:func:`casadi_keyframe.augmented_lagrangian.solve_augmented`), and every one of them tears
the cape on the way: forces of the size that lands it stretch springs 2-4 times and push
cloth into the body.  (On the full 26 x 16 cape: IPOPT 2.8 cm rms, 4.7 % of the width, in 59
iterations, stretch 2.84; three rounds of multipliers 0.26 m.)  Along the gradient the
objective curves ~1000 times more sharply than along random directions (the gradient sits
on cloth falling onto the shoulders at 4 m/s in the first steps), and seen from where the
passive cape ends, the walk's cape lies behind the body.  What lands, and stays physical,
is a better start: by default (``guess="tracking"``) a PD controller pulls the cape along a
crossfade of the two shapes (:func:`reference_path`) and its last two steps put it on the
walk's state (:func:`tracking_forces`, :func:`tracking_guess`).  That blend is clean (26 x
16: stretch 1.16 and no particle in the body, where the passive blend reaches 1.49 and 1.2
cm; 24 m/s^2 rms, 286 m/s^2 on one particle in the landing step) but it is a guess, not an
optimum, and no optimizer here lowers its forces: on the keyframe the gradient is the
control cost's alone and points off the forces that keep the landing, where the keyframe
term curves so sharply (about 1e5 N^-2 along it, 8 x 6) that the best step gains some 1e-11,
below L-BFGS-B's stopping test.  It stops after 1-4 iterations, also with multipliers or
with the keyframe weights 100 times lower in a first round; IPOPT takes 31 and lowers the
control cost by 0.4 % while leaving the keyframe 0.4 mm (8 x 6: control cost 0.0246 in
every case).  Do not add ``continuation``: the guess resampled to 2 dt no longer lands, and
the solve ends 18 cm off (13 x 8).  ``guess="passive"`` starts from zero forces, as the
paper did.

The gradient is the exact hand adjoint of the linearized scheme: the paper's swapped adjoint
is poor in resting contact and over long horizons (notebooks/gradient_accuracy.ipynb;
cloth_arch and cloth_toss measure what it costs there), and this problem has contact
throughout and 60 steps.  ``adjoint="swapped"`` runs the paper's method.
"""
from __future__ import annotations

import numpy as np

from casadi_keyframe.objectives import Smoothness, StateKeyframe
from casadi_keyframe.scenes.animations import fall, transition
from casadi_keyframe.scenes.capes import cached_clip, cape_model
from casadi_keyframe.scenes.cloths import cloth_problem
from casadi_keyframe.scenes.maths import smoothstep
from casadi_keyframe.scenes.skeleton import Character

SOLVE = {"method": "lbfgsb", "maxiter": 300}
GUESSES = ("tracking", "passive")
RANGES = {"rows": "[2, inf)", "cols": "[3, inf)", "steps": "[2, inf)", "dt": "(0, inf)",
          "t_a": "[0, inf)", "t_b": "[0, inf)", "window": "(0, inf)",
          "position_weight": "[0, inf)", "velocity_weight": "[0, inf)", "alpha": "[0, inf)",
          "temporal": "[0, inf)", "guess": GUESSES, "adjoint": ("exact", "swapped")}


def build(rows: int = 26, cols: int = 16, steps: int | None = None, dt: float = 1 / 60,
          t_a: float = 0.8, t_b: float = 0.6, window: float | None = None,
          position_weight: float = 400.0, velocity_weight: float = 4.0, alpha: float = 1e-4,
          temporal: float = 1e-7, guess: str = "tracking", adjoint: str = "exact"):
    steps = blend_steps(steps, window, dt)
    fall_start, walk_start = frame_of(t_a, dt, "t_a"), frame_of(t_b, dt, "t_b")
    character = Character()
    fall_end = fall(character).end
    window = steps * dt
    if not 0 <= t_a <= fall_end - window:
        raise ValueError(f"cape_blend: the blend [t_a, t_a + window] = [{t_a:.6g}, "
                         f"{t_a + window:.6g}] s must lie inside the fall clip [0, "
                         f"{fall_end:.6g}] s")
    fall_model, fall_traj, fall_motion = cached_clip("fall", rows, cols, t_a + window, dt)
    walk_model, walk_traj, walk_motion = cached_clip("walk", rows, cols, t_b + window, dt)
    motion = transition(fall_motion, walk_motion, t_a, t_b, window)
    model = cape_model(character, motion.shifted(-t_a), rows=rows, cols=cols, dt=dt)
    x0, v0 = fall_traj.x[fall_start], fall_traj.v[fall_start]
    target_x = walk_traj.x[walk_start + steps] + motion.offset
    target_v = walk_traj.v[walk_start + steps]
    _check_attached(model, x0, 0.0, t_a, "start state (fall clip)")
    _check_attached(model, target_x, steps * dt, t_a + window, "target (walk clip + offset)")
    m = model.masses.mean()
    objective = (StateKeyframe(steps, x=target_x, v=target_v,
                               position_weight=position_weight / model.n,
                               velocity_weight=velocity_weight / model.n)
                 + Smoothness(alpha / m, temporal=temporal / m))
    scene = {"character": character, "animation": motion, "t_a": t_a, "t_b": t_b,
             "window": window, "view": (15, -60),
             "clips": {"fall": (fall_model, fall_traj), "walk": (walk_model, walk_traj)}}
    prob = cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cape_blend",
                         x0=x0, v0=v0, adjoint=adjoint, scene=scene)  # forces on free particles
    if guess == "passive":
        return prob
    path = reference_path(character, motion, x0, (walk_traj, walk_motion, walk_start), steps,
                          dt)
    return prob.with_guess(tracking_guess(prob, path, (target_x, target_v)))


def blend_steps(steps, window, dt: float) -> int:
    """The blend's length in steps: ``steps``, or ``window`` s (default 1 s) on the time
    grid; both given, they must agree."""
    if steps is None:
        steps = frame_of(1.0 if window is None else window, dt, "window")
    elif window is not None and frame_of(window, dt, "window") != steps:
        raise ValueError(f"cape_blend: steps = {steps} and window = {window:.6g} s disagree at "
                         f"dt = {dt:.6g} s; give one of them")
    if int(steps) != steps or steps < 2:
        raise ValueError(f"cape_blend: the blend needs a whole number of steps, at least 2 (the "
                         f"tracking guess lands by two steps), got {steps} (window / dt)")
    return int(steps)


def frame_of(t: float, dt: float, what: str) -> int:
    """The frame at time ``t`` on a grid of step ``dt``, or a ValueError if t is off it."""
    if not np.isfinite(t):
        raise ValueError(f"cape_blend: {what} must be a finite time in s, got {t}")
    k = int(round(t / dt))
    if abs(t - k * dt) > 1e-9 * max(1.0, abs(t)):
        raise ValueError(f"cape_blend: {what} = {t:.6g} s is not a whole number of steps of "
                         f"dt = {dt:.6g} s ({t / dt:.6g} steps); choose {what} on the time grid")
    return k


def _check_attached(model, x, t: float, clock: float, what: str) -> None:
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
    crossfade with it pulls the hem through the head (26 x 16 cape: tracking forces of 220
    m/s^2 rms and stretch 1.9, against 24 m/s^2 and 1.16 with the shape held)."""
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
                    landing_steps: int = 2) -> np.ndarray:
    """Per-step forces ``(steps, n, 3)`` of a PD controller that pulls every particle of
    ``prob``'s cape along ``path`` (``(steps + 1, n, 3)``) from its start: ``m (a* + kp (x* -
    x) + kd (v* - v) - g) + drag m v*`` with ``kp = (2 pi f)^2``, ``kd = 2 damping sqrt(kp)``,
    f rising linearly from ``start_frequency`` (default: ``frequency``) to ``frequency`` Hz (at
    most ``1 / (8 dt)``: the PD force is explicit in the step), reference velocities and
    accelerations by differences of the path.  Contacts and the cloth's springs still act,
    so the cape yields where the path runs into the body.  With ``end = (x1, v1)`` the last
    ``landing_steps`` instead follow a cubic from the state the controller reached to exactly
    that state (:func:`landing_path`), by inverse steps (the integrator's ``force_for``).
    Two steps is the least that sets positions and velocities, and the best measured: an
    inverse step also cancels the contact forces along the cubic, so a longer landing costs
    more, not less (26 x 16 cape: at most 286 m/s^2 on one particle over 2 steps, 929 over
    10).  Run closed-loop through the problem's integrator; replayed open-loop, the forces give the
    same motion.  (Exact inverse dynamics along the whole path does not yield: it cancels the
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
    land_from = steps if end is None else steps - min(max(landing_steps, 2), steps)
    x, v, dv = prob.x0, prob.v0, None
    forces = np.zeros((steps,) + x.shape)
    for n in range(steps):
        if n == land_from:
            land = landing_path(x, v, *end, steps - n, dt)
        if n >= land_from:
            forces[n] = integrator.force_for(model, x, v, (land[n - land_from + 1] - x) / dt,
                                             n, dt)
        else:
            forces[n] = m * (a_ref[n] + kp[n] * (path[n] - x) + kd[n] * (v_ref[n] - v) - g
                             + model.params.air_drag * v_ref[n])
        x, v, dv = integrator.step(model, x, v, forces[n], n, dt, dv)
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
    itself (26 x 16 cape: control cost 0.080 held at 8 Hz, 0.014 ramped up from 0.5 Hz;
    8 x 6 over 0.5 s: 0.12 held, 0.066 from 4 Hz, 0.52 from 0.5 Hz)."""
    free = prob.controls.idx
    candidates = [tracking_forces(prob, path, end, start_frequency=f)[:, free].ravel()
                  for f in start_frequencies]
    return min(candidates, key=lambda u: prob.control_cost(u)[0])
