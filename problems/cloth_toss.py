"""Fig. 5: only the initial velocities are optimized so that a tossed sheet flies through a
small ring (its centre of mass passes the ring's centre) and turns over in the air.

The sheet starts flat, thrown with the ballistic velocity that would carry its centre of mass
to the ring's centre; the controls are per-particle corrections to it, bounded by
``max_speed``, with ``alpha`` on their mean square (the mean, so the weight means the same at
every resolution).  Keyframes: the centre of mass at the ring's centre at ``ring_at`` of the
clip, and the four corners half a turn about the y axis at ``flip_at``; the clip goes on
to the landing on the ground (1.2 s), which the default contact keeps whole (under the
paper's penalty springs, ``collision="penalty"``, it tears the sheet).
``SOLVE`` solves 12 x 12 and 25 x 25 sheets of the same cloth first, since a rigid spin is
one smooth field among thousands of controls that a direct search at 50 x 50 never finds;
``StrainLimit`` keeps springs under 1.2 times their length; ``friction`` is the ground's
Coulomb coefficient (0: frictionless).  The exact adjoint is the
default: with the paper's swapped adjoint the sheet never turns.  Measurements behind these
choices: ``docs/problem_notes.md``.
"""
import numpy as np

from casadi_keyframe.controls import InitialVelocity
from casadi_keyframe.models import COLLISIONS, DEFAULT_COLLISION, ClothModel
from casadi_keyframe.models.contact.colliders import Contact, Plane
from casadi_keyframe.objectives import (CenterOfMassKeyframe, ParticleKeyframe, Smoothness,
                                        StrainLimit)
from casadi_keyframe.scenes.cloths import cloth_problem, rotate_about
from casadi_keyframe.views import ClothView, Ring

SOLVE = {"method": "lbfgsb", "maxiter": 200, "gradient": "adjoint",
         "resolutions": [{"rows": 12, "cols": 12}, {"rows": 25, "cols": 25}]}
RANGES = {"rows": "[2, inf)", "cols": "[2, inf)", "steps": "[2, inf)", "dt": "(0, inf)",
          "size": "(0, inf)", "height": "(0, inf)", "ring_radius": "(0, inf)",
          "ring_weight": "[0, inf)", "corner_weight": "[0, inf)", "alpha": "[0, inf)",
          "max_speed": "(0, inf)", "strain_limit": "[1, inf)", "strain_weight": "[0, inf)",
          "ring_at": "(0, 1]", "flip_at": "(0, 1]", "collision": COLLISIONS,
          "friction": "[0, inf)"}


def build(rows: int = 50, cols: int = 50, steps: int = 72, dt: float = 1 / 60,
          size: float = 1.0, height: float = 1.0,
          ring_center: tuple[float, float, float] = (1.5, 0.0, 2.0),
          ring_radius: float = 0.35, ring_weight: float = 100.0, corner_weight: float = 10.0,
          alpha: float = 0.36, max_speed: float = 8.0, strain_limit: float = 1.2,
          strain_weight: float = 1e3, ring_at: float = 0.445, flip_at: float = 0.806,
          collision: str = DEFAULT_COLLISION, friction: float = 0.0):
    ground = Plane((0.0, 0.0, 0.0), contact=Contact(friction=friction))
    model = ClothModel.grid(rows, cols, width=size, height=size, plane="xy", mass=0.3,
                            origin=(-size / 2, -size / 2, height), colliders=[ground],
                            collision=collision)
    rest = model.rest_positions
    center, ring = rest.mean(0), np.asarray(ring_center, float)
    gravity = np.asarray(model.params.gravity)
    ring_frame, flip_frame = int(round(ring_at * steps)), int(round(flip_at * steps))
    if not 1 <= ring_frame < flip_frame <= steps:
        raise ValueError(f"cloth_toss: the ring's frame {ring_frame} (ring_at {ring_at:g} of "
                         f"{steps} steps) must come after the throw and before the flip's "
                         f"{flip_frame} (flip_at {flip_at:g}): choose ring_at < flip_at, or "
                         "more steps")
    flight = ring_frame * dt
    throw = (ring - center - 0.5 * gravity * flight ** 2) / flight

    def ballistic(frame):
        t = frame * dt
        return center + throw * t + 0.5 * gravity * t ** 2

    corners = np.array([0, cols - 1, (rows - 1) * cols, rows * cols - 1])
    flipped = rotate_about(rest[corners], center, (0.0, 1.0, 0.0), np.pi)
    flipped += ballistic(flip_frame) - center
    objective = (CenterOfMassKeyframe(ring_frame, x=ring, position_weight=ring_weight,
                                      tolerance=0.03)
                 + ParticleKeyframe(flip_frame, corners, x=flipped, position_weight=corner_weight,
                                    tolerance=0.15)
                 + Smoothness(alpha / model.n)
                 + StrainLimit(strain_limit, strain_weight))
    view = ClothView(camera=(15, -80), ring=Ring(center=ring, radius=ring_radius,
                                                 normal=throw / np.linalg.norm(throw)))
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cloth_toss",
                         v0=np.tile(throw, (model.n, 1)),
                         controls=InitialVelocity(lower=-max_speed, upper=max_speed),
                         view=view)
