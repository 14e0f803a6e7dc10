"""Fig. 5: only the initial velocities are optimized so that a tossed sheet flies through a
small ring (its centre of mass passes the ring's centre) and turns over in the air.

The sheet starts flat, thrown with the ballistic velocity that would carry its centre of mass
to the ring's centre (no drag, no spin); the controls are per-particle corrections to that
initial velocity.  Keyframes: the centre of mass at the ring's centre at ``ring_frame``
(``ring_at`` of the clip); the four corners, at ``flip_frame`` (``flip_at``), where a half
turn about the y axis puts them around the ballistic centre of mass (upside down, still in
the air).  The clip ends 4 frames later, 1.03 s after the throw, before the sheet reaches the
ground (see "Staying physical").  Each
velocity component is bounded by ``max_speed`` and ``alpha`` penalises the mean squared
correction ``|u|^2 / n`` (the mean, so the weight means the same at every resolution: with
the sum, a 50 x 50 sheet paid 70 times the 6 x 6 sheet's price for the same spin and L-BFGS-B
crawled, objective 20.9 to 20.5 in 21 iterations): per-particle initial velocities have a
large near-null space (patterns the stiff springs absorb at once) that the optimizer would
otherwise wander into.

Coarse to fine.  Searched directly, the 50 x 50 sheet never turns over (26 iterations, the
corners 0.98 m off): a rigid spin is one smooth velocity field among 7500 controls, most of
them patterns the springs absorb.  ``SOLVE`` therefore solves 12 x 12 and 25 x 25 sheets of
the same cloth first (``resolutions``), each search starting from the last one's velocities
interpolated onto the finer mesh; the 12 x 12 search finds the turn in under 20 s.

Staying physical.  ``StrainLimit(strain_limit, strain_weight)`` keeps springs under 1.2
times their length; without it the throw found stretches them 1.46 times in its first steps.
The clip used to go on to 72 steps (1.2 s, the same keyframes), the sheet landing on the
ground tilted at 6 m/s, and that landing tore it: each particle crosses the ground's 1 cm
contact layer within one step of 1/60 s before the penalty spring sees it, and the spring
then throws it out again.
A rigid spin alone (25 x 25, no optimization) stretched springs 5.0 times on landing, 1.65 at
dt / 2, 1.19 at dt / 4; thicker, softer or more damped ground contact (3-5 cm, 200 N/m,
100 N s/m) still 2.9-3.5; the optimized 50 x 50 toss 4.95, next to the integrator's
blow-up test, and a 12 x 12 throw carried to 25 x 25 blew up there.  Counting the landing in
the strain limit stopped the 12 x 12 search after 6 iterations, the sheet unturned; a 1 s
clip with the flip at 0.8 s ended 3.8 cm and 0.17 m off.  A limit
of the penalty contact under a fixed step, not of the controls: with ``steps=72`` the sheet
lands and tears (the 50 x 50 toss still 2.5 times at dt / 4).

Which gradient gets there (50 x 50, ``benchmarks/cloth_figures.py``, one BLAS thread; the
centre of mass's miss at the ring, the corners' rms miss, the largest spring stretch,
how far the sheet has turned at the flip frame, iterations per mesh, CPU seconds):

    =================  ============  =============  =======  ======  ==============  =====
    route              ring (COM)    corners (rms)  stretch  turned  iterations      CPU s
    =================  ============  =============  =======  ======  ==============  =====
    exact adjoint      1.6 cm        0.095 m        1.20     179     26 + 48 + 23    220
    swapped (paper's)  6.2 cm        0.78 m         1.17     2       7 + 5 + 4       67
    =================  ============  =============  =======  ======  ==============  =====

(iterations on the 12 x 12, 25 x 25 and 50 x 50 meshes; both stop on L-BFGS-B's
relative-reduction test).  With the swapped adjoint the sheet never turns over.

The exact adjoint is the default.  At 6 x 6 (the 72-step clip, before the strain limit) the
paper's swapped adjoint stalled L-BFGS-B too (6 iterations, objective 10.6, corners 0.71 m
off; exact: objective 1.6, corners 0.17 m off): the velocity patterns the springs absorb in
the first steps are exactly where it is wrong (cosine 0.46 to the exact gradient at random
0.3 m/s perturbations).  ``--gradient swapped`` runs the paper's method.
"""
import numpy as np

from casadi_keyframe.controls import InitialVelocity
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.colliders import Plane
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
          "ring_at": "(0, 1]", "flip_at": "(0, 1]"}


def build(rows: int = 50, cols: int = 50, steps: int = 62, dt: float = 1 / 60,
          size: float = 1.0, height: float = 1.0,
          ring_center: tuple[float, float, float] = (1.5, 0.0, 2.0),
          ring_radius: float = 0.35, ring_weight: float = 100.0, corner_weight: float = 10.0,
          alpha: float = 0.36, max_speed: float = 8.0, strain_limit: float = 1.2,
          strain_weight: float = 1e3, ring_at: float = 0.52, flip_at: float = 0.94):
    ground = Plane((0.0, 0.0, 0.0))
    model = ClothModel.grid(rows, cols, width=size, height=size, plane="xy", mass=0.3,
                            origin=(-size / 2, -size / 2, height), colliders=[ground])
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
    objective = (CenterOfMassKeyframe(ring_frame, x=ring, position_weight=ring_weight)
                 + ParticleKeyframe(flip_frame, corners, x=flipped, position_weight=corner_weight)
                 + Smoothness(alpha / model.n)
                 + StrainLimit(strain_limit, strain_weight))
    view = ClothView(camera=(15, -80), ring=Ring(center=ring, radius=ring_radius,
                                                 normal=throw / np.linalg.norm(throw)))
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cloth_toss",
                         v0=np.tile(throw, (model.n, 1)),
                         controls=InitialVelocity(lower=-max_speed, upper=max_speed),
                         view=view)
