"""Fig. 6: a cape blended from a fall into a walk, a boundary-value problem.

Two passive clips of the same cape (:func:`casadi_keyframe.scenes.capes.simulate_clip`): a
stunt double falls 2 m and lands face down (``fall``), an actor walks (``walk``).  The blend
starts from the fall clip's cape at its time ``t_a`` (position AND velocity of every
particle) while the character moves through ``animations.transition(fall, walk, t_a, t_b,
window)``; per-step forces on the free (not sewn-on) particles must bring the cape,
``window`` s later, onto the walk clip's cape at its time ``t_b + window``, positions and
velocities, the positions moved by the transition's horizontal ``offset`` (which lines the
walk up with where the body lands).  Minimal, smooth forces: :class:`Smoothness` with a
temporal term.  The problem's ``view`` (:class:`casadi_keyframe.views.BlendView`) refers to
the character, the transition (``animation``, on the fall clip's clock: the blend's frame k
is at ``t_a + k dt``) and both clips (model and trajectory, shared, not copies: the fall's
frame ``t_a / dt + k`` and the walk's ``t_b / dt + k`` go with the blend's frame k), for
drawing the three side by side.

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
(:func:`casadi_keyframe.optimize.solve_augmented`), and every one of them tears
the cape on the way: forces of the size that lands it stretch springs 2-4 times and push
cloth into the body.  (On the full 26 x 16 cape: IPOPT 2.8 cm rms, 4.7 % of the width, in 59
iterations, stretch 2.84; three rounds of multipliers 0.26 m.  With the Choi-Ko law and
coarse to fine in space, IPOPT on 8 x 6, 13 x 8, then 26 x 16 meshes for 30 min of CPU
(24, 204 and 14 iterations) ended 7.8 cm and 0.91 m/s off, stretch 4.8, 4.9 cm in the
body.)  Along the gradient the
objective curves ~1000 times more sharply than along random directions (the gradient sits
on cloth falling onto the shoulders at 4 m/s in the first steps), and seen from where the
passive cape ends, the walk's cape lies behind the body.  What lands, and stays physical,
is a better start: by default (``guess="tracking"``) a PD controller pulls the cape along a
crossfade of the two shapes and its last two steps put it on the walk's state
(:mod:`casadi_keyframe.scenes.cape_tracking`).  That blend is clean (26 x
16: stretch 1.16 and no particle in the body, where the passive blend reaches 1.49 and 1.2
cm; 24 m/s^2 rms, 286 m/s^2 on one particle in the landing step) but it is a guess, not an
optimum, and no penalty search lowers its forces: on the keyframe the gradient is the
control cost's alone and points off the forces that keep the landing, where the keyframe
term curves so sharply (about 1e5 N^-2 along it, 8 x 6) that the best step gains some 1e-11,
below L-BFGS-B's stopping test.  It stops after 1-4 iterations, also with multipliers or
with the keyframe weights 100 times lower in a first round; IPOPT takes 31 and lowers the
control cost by 0.4 % while leaving the keyframe 0.4 mm (8 x 6: control cost 0.0246 in
every case).  Holding the landing as a constraint does it:
:func:`casadi_keyframe.optimize.lower_effort` (quadratic steps on the last 12 steps'
forces, the keyframe's Jacobian from one adjoint sweep per component) lowers the 26 x 16
guess's control cost from 0.0204 to 0.0158 (-22.8 %) in one kept step and 417 s of CPU,
the landing 0.77 mm and 1.6 cm/s off over the free particles, stretch 1.13 and no particle
in the body, as the guess (8 x 6: -36 % in 5 steps, 57 s).  The dynamics are only piecewise
smooth (the landing jumps by ~0.4 mm rms for relative control changes of 1e-6), which is
why it holds a tolerance, not the exact landing.  Do not add ``continuation``: the guess
resampled to 2 dt no longer lands, and the solve ends 18 cm off (13 x 8).
``guess="passive"`` starts from zero forces, as the paper did.

The tracking guess's choices, measured on the 26 x 16 cape: crossfading to the fall clip's
own cape, which topples over the head, instead of holding its shape at ``t_a`` pulls the
hem through the head (tracking forces of 220 m/s^2 rms and stretch 1.9, against 24 m/s^2
and 1.16); landing over 2 steps takes at most 286 m/s^2 on one particle, over 10 steps
929; over 1 s the control cost is 0.014 with the gain ramped up from 0.5 Hz and 0.080 with
it held at 8 Hz, but over 0.5 s (8 x 6) 0.12 held, 0.066 from 4 Hz and 0.52 from 0.5 Hz,
so :func:`~casadi_keyframe.scenes.cape_tracking.tracking_guess` tries several ramps.

The gradient is the exact hand adjoint of the linearized scheme: the paper's swapped adjoint
is poor in resting contact and over long horizons (notebooks/gradient_accuracy.ipynb;
cloth_arch and cloth_toss measure what it costs there), and this problem has contact
throughout and 60 steps.  ``--gradient swapped`` runs the paper's method.
"""
from __future__ import annotations

from casadi_keyframe.checks import frame_at
from casadi_keyframe.objectives import Smoothness, StateKeyframe
from casadi_keyframe.scenes.animations import fall, transition
from casadi_keyframe.scenes.cape_tracking import (blend_steps, check_attached, reference_path,
                                                  tracking_guess)
from casadi_keyframe.scenes.capes import cached_clip, cape_model
from casadi_keyframe.scenes.cloths import cloth_problem
from casadi_keyframe.scenes.skeleton import Character
from casadi_keyframe.views import BlendView, Clip

SOLVE = {"method": "lbfgsb", "maxiter": 300, "gradient": "adjoint"}
GUESSES = ("tracking", "passive")
RANGES = {"rows": "[2, inf)", "cols": "[3, inf)", "steps": "[2, inf)", "dt": "(0, inf)",
          "t_a": "[0, inf)", "t_b": "[0, inf)", "window": "(0, inf)",
          "position_weight": "[0, inf)", "velocity_weight": "[0, inf)", "alpha": "[0, inf)",
          "temporal": "[0, inf)", "guess": GUESSES}


def build(rows: int = 26, cols: int = 16, steps: int | None = None, dt: float = 1 / 60,
          t_a: float = 0.8, t_b: float = 0.6, window: float | None = None,
          position_weight: float = 400.0, velocity_weight: float = 4.0, alpha: float = 1e-4,
          temporal: float = 1e-7, guess: str = "tracking"):
    steps = blend_steps(steps, window, dt)
    fall_start = frame_at(t_a, dt, "cape_blend: t_a")
    walk_start = frame_at(t_b, dt, "cape_blend: t_b")
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
    check_attached(model, x0, 0.0, t_a, "start state (fall clip)")
    check_attached(model, target_x, steps * dt, t_a + window, "target (walk clip + offset)")
    m = model.masses.mean()
    objective = (StateKeyframe(steps, x=target_x, v=target_v,
                               position_weight=position_weight / model.n,
                               velocity_weight=velocity_weight / model.n)
                 + Smoothness(alpha / m, temporal=temporal / m))
    view = BlendView(camera=(15, 35), character=character, animation=motion, t_a=t_a, t_b=t_b,
                     fall=Clip(fall_model, fall_traj), walk=Clip(walk_model, walk_traj))
    prob = cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cape_blend",
                         x0=x0, v0=v0, view=view)  # forces on free particles
    if guess == "passive":
        return prob
    path = reference_path(character, motion, x0, (walk_traj, walk_motion, walk_start), steps,
                          dt)
    return prob.with_guess(tracking_guess(prob, path, (target_x, target_v)))
