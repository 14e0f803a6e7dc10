"""Fig. 6: a cape blended from a fall into a walk, a boundary-value problem.

Two passive clips of the same cape (:func:`casadi_keyframe.scenes.capes.simulate_clip`): a
stunt double falls and lands face down (``fall``), an actor walks (``walk``).  The blend
starts from the fall clip's cape at ``t_a`` (positions and velocities) while the character
moves through ``animations.transition(fall, walk, t_a, t_b, window)``; per-step forces on the
free particles must bring it, ``window`` s later, onto the walk clip's cape at ``t_b +
window``, positions and velocities, with minimal, smooth forces (:class:`Smoothness` with a
temporal term).  ``t_a = 0.8`` s is the last moment the cape streams out behind the body,
before it topples over the head; ``t_b = 0.6`` s keeps the blended legs shallowest.  The
weights are divided by the particle count and the mean particle mass, so they mean the same
at every resolution.  From zero forces (``guess="passive"``, the paper's start) gradient
searches stall far off or tear the cape, so the default start is a tracking guess
(:mod:`casadi_keyframe.scenes.cape_tracking`) that lands on the walk's state; from zero
forces ``SOLVE`` asks for multiple shooting.  ``--method transcription`` (with
``collision=penalty``, the contact the plan pays for) meets the goal from the cape held
still (``--option start=rest``) without either, in less time, but at many times the
effort this route ends with, so ``SOLVE`` does not choose it.  ``contact`` > 1 makes the
body's contact that many times softer and thicker (a homotopy level); ``collision`` how the
body is touched; ``friction`` the Coulomb coefficient of the body and the ground (0:
frictionless).
``rest_band``: the strain band below rest over which the linearized step's spring stiffness
turns smoothly (``ClothParams.rest_band``; 0, the default, is the paper's step).  ``body``
what it is: its capsules ("capsules"), their surface as a triangle mesh animated per
frame ("mesh"), or a mesh file read as the character (a PC2 cache beside its rest OBJ at one
frame per ``dt``, or a time-sampled USD; t = 0 is the blend's start, as
``scenes.body_meshes.write_body`` writes it).  Measurements behind these choices:
``docs/problem_notes.md``.
"""
from __future__ import annotations

from dataclasses import replace

from casadi_keyframe.checks import frame_at
from casadi_keyframe.models import COLLISIONS, DEFAULT_COLLISION
from casadi_keyframe.objectives import Smoothness, StateKeyframe
from casadi_keyframe.scenes.animations import fall, transition
from casadi_keyframe.scenes.body_meshes import cape_body, cape_body_file
from casadi_keyframe.scenes.cape_tracking import (blend_steps, check_attached, reference_path,
                                                  tracking_guess)
from casadi_keyframe.scenes.capes import CAPE_PARAMS, cached_clip, cape_contacts, cape_model
from casadi_keyframe.scenes.cloths import cloth_problem
from casadi_keyframe.scenes.skeleton import Character
from casadi_keyframe.views import BlendView, Clip

GUESSES = ("tracking", "passive")


def SOLVE(guess: str = "tracking", **_) -> dict:
    """From the tracking guess a search that stops at the goal; from zero forces multiple
    shooting, its nodes on the blend's reference path (:func:`path`), since one gradient
    through the whole blend stalls far off, its controls then landed by the finish's steps
    on the last forces (no single-shooting polish: it stalls at the dynamics' kinks).
    Either way the finish then lowers the forces with the keyframe held (``--finish``),
    which no penalty search does from a landing."""
    solve = {"method": "lbfgsb", "maxiter": 300, "gradient": "adjoint", "finish": "effort"}
    return solve if guess != "passive" else {
        **solve, "shooting": {"segments": 6, "init": path, "polish": False}}


def path(prob):
    """The blend's reference path (:func:`reference_path`: the cape held in the torso's
    frame crossfaded into the walk clip's) for ``prob`` built by this file: where multiple
    shooting's nodes start."""
    view = prob.view
    motion, dt = view.animation, prob.dt
    walk = (view.walk.trajectory, motion.second, frame_at(view.t_b, dt, "cape_blend: t_b"))
    return reference_path(view.character, motion, prob.x0, walk, prob.steps, dt)
RANGES = {"rows": "[2, inf)", "cols": "[3, inf)", "steps": "[2, inf)", "dt": "(0, inf)",
          "t_a": "[0, inf)", "t_b": "[0, inf)", "window": "(0, inf)",
          "position_weight": "[0, inf)", "velocity_weight": "[0, inf)", "alpha": "[0, inf)",
          "temporal": "[0, inf)", "guess": GUESSES, "contact": "[1, inf)",
          "collision": COLLISIONS, "friction": "[0, inf)", "rest_band": "[0, 1)"}


def build(rows: int = 26, cols: int = 16, steps: int | None = None, dt: float = 1 / 60,
          t_a: float = 0.8, t_b: float = 0.6, window: float | None = None,
          position_weight: float = 400.0, velocity_weight: float = 4.0, alpha: float = 1e-4,
          temporal: float = 1e-7, guess: str = "tracking", contact: float = 1.0,
          collision: str = DEFAULT_COLLISION, friction: float = 0.0,
          body: str = "capsules", rest_band: float = 0.0):
    steps = blend_steps(steps, window, dt)
    contacts = _contacts(rows, cols, dt, contact, friction)
    given = cape_body_file("cape_blend", body, dt, contacts["body"])  # before any simulation
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
    model = cape_model(character, motion.shifted(-t_a), rows=rows, cols=cols, dt=dt,
                       contacts=contacts, collision=collision,
                       params=replace(CAPE_PARAMS, rest_band=rest_band) if rest_band else None,
                       body=cape_body("cape_blend", body, character, motion.shifted(-t_a),
                                      window, dt, contacts["body"], given))
    x0, v0 = fall_traj.x[fall_start], fall_traj.v[fall_start]
    target_x = walk_traj.x[walk_start + steps] + motion.offset
    target_v = walk_traj.v[walk_start + steps]
    check_attached(model, x0, 0.0, t_a, "start state (fall clip)")
    check_attached(model, target_x, steps * dt, t_a + window, "target (walk clip + offset)")
    m = model.masses.mean()
    objective = (StateKeyframe(steps, x=target_x, v=target_v,
                               position_weight=position_weight / model.n,
                               velocity_weight=velocity_weight / model.n,
                               tolerance=(0.006, 0.05))
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


def _contacts(rows, cols, dt, softness, friction=0.0):
    """The cape's own contact laws (:func:`cape_contacts`), the body's ``softness`` times
    softer, thicker and more gradual (1: the model's own), the body's and the ground's with
    Coulomb coefficient ``friction``."""
    contacts = cape_contacts(0.4 / (rows * cols), min(0.6 / (cols - 1), 1.0 / (rows - 1)), dt)
    body = contacts["body"]
    contacts["body"] = replace(body, stiffness=body.stiffness / softness,
                               damping=body.damping / softness,
                               thickness=body.thickness * softness, width=body.width * softness)
    for name in ("body", "ground"):
        contacts[name] = replace(contacts[name], friction=friction)
    return contacts
