"""Fig. 5: only the initial velocities are optimized so that a tossed sheet flies through a
small ring (its centre of mass passes the ring's centre) and turns over in the air.

The sheet starts flat, thrown with the ballistic velocity that would carry its centre of mass
to the ring's centre (no drag, no spin); the controls are per-particle corrections to that
initial velocity.  Keyframes: the centre of mass at the ring's centre at ``ring_frame``; the
four corners, at ``flip_frame``, where a half turn about the y axis puts them around the
ballistic centre of mass (upside down, still in the air); then it falls to the ground.  Each
velocity component is bounded by ``max_speed`` and ``alpha`` penalises the mean squared
correction ``|u|^2 / n`` (the mean, so the weight means the same at every resolution: with
the sum, a 50 x 50 sheet paid 70 times the 6 x 6 sheet's price for the same spin and L-BFGS-B
crawled, objective 20.9 to 20.5 in 21 iterations): per-particle initial velocities have a
large near-null space (patterns the stiff springs absorb at once) that the optimizer would
otherwise wander into.

The default gradient is the exact hand adjoint of the linearized step: with the paper's
swapped adjoint L-BFGS-B stalls here (6 x 6 sheet: 6 iterations, objective 10.6, corners
0.71 m off; exact: objective 1.6, corners 0.17 m off), because the velocity patterns the
springs absorb in the first steps are exactly where the swapped adjoint is wrong (cosine
0.46 to the exact gradient at random 0.3 m/s perturbations).  ``--gradient swapped``
runs the paper's method.
"""
import numpy as np

from casadi_keyframe.controls import InitialVelocity
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.colliders import Plane
from casadi_keyframe.objectives import CenterOfMassKeyframe, ParticleKeyframe, Smoothness
from casadi_keyframe.scenes.cloths import cloth_problem, rotate_about
from casadi_keyframe.views import ClothView, Ring

SOLVE = {"method": "lbfgsb", "maxiter": 200, "gradient": "adjoint"}
RANGES = {"rows": "[2, inf)", "cols": "[2, inf)", "steps": "[2, inf)", "dt": "(0, inf)",
          "size": "(0, inf)", "height": "(0, inf)", "ring_radius": "(0, inf)",
          "ring_weight": "[0, inf)", "corner_weight": "[0, inf)", "alpha": "[0, inf)",
          "max_speed": "(0, inf)"}


def build(rows: int = 50, cols: int = 50, steps: int = 72, dt: float = 1 / 60,
          size: float = 1.0, height: float = 1.0,
          ring_center: tuple[float, float, float] = (1.5, 0.0, 2.0),
          ring_radius: float = 0.35, ring_weight: float = 100.0, corner_weight: float = 10.0,
          alpha: float = 0.36, max_speed: float = 8.0):
    ground = Plane((0.0, 0.0, 0.0))
    model = ClothModel.grid(rows, cols, width=size, height=size, plane="xy", mass=0.3,
                            origin=(-size / 2, -size / 2, height), colliders=[ground])
    rest = model.rest_positions
    center, ring = rest.mean(0), np.asarray(ring_center, float)
    gravity = np.asarray(model.params.gravity)
    ring_frame, flip_frame = int(round(0.45 * steps)), int(round(0.8 * steps))
    flight = ring_frame * dt
    throw = (ring - center - 0.5 * gravity * flight ** 2) / flight

    def ballistic(frame):
        t = frame * dt
        return center + throw * t + 0.5 * gravity * t ** 2

    corners = np.array([0, cols - 1, (rows - 1) * cols, rows * cols - 1])
    flipped = rotate_about(rest[corners], center, (0.0, 1.0, 0.0), np.pi)
    flipped += ballistic(flip_frame) - center
    objective = (CenterOfMassKeyframe(ring_frame, x=ring, position_weight=ring_weight)
                 + ParticleKeyframe(flip_frame, corners, x=flipped, position_weight=corner_weight)
                 + Smoothness(alpha / model.n))
    view = ClothView(camera=(15, -80), ring=Ring(center=ring, radius=ring_radius,
                                                 normal=throw / np.linalg.norm(throw)))
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cloth_toss",
                         v0=np.tile(throw, (model.n, 1)),
                         controls=InitialVelocity(lower=-max_speed, upper=max_speed),
                         view=view)
