"""Fig. 1: a sheet lying on the ground bends up into an arch and holds it.

Per-step control forces on every particle; the keyframe at the last frame asks for the sheet
rolled into a half cylinder of the same arc length, its two ends on the ground, at rest.  The
optimizer starts from forces that carry the sheet's weight: from zero forces a sheet resting
on the ground must first outweigh the contact before it moves at all, so its gradient there
is almost zero (measured: L-BFGS-B stalls with the sheet flat).
"""
import numpy as np

from casadi_keyframe.cloths import bend_into_arch, cloth_problem, weight_support
from casadi_keyframe.controls import StepForces
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.colliders import Plane
from casadi_keyframe.objectives import StateKeyframe, Smoothness

SOLVE = {"method": "lbfgsb", "maxiter": 150}


def build(rows: int = 15, cols: int = 15, steps: int = 60, dt: float = 1 / 60,
          size: float = 1.0, weight: float = 100.0, alpha: float = 1e-4,
          adjoint: str = "swapped"):
    ground = Plane((0.0, 0.0, 0.0))
    model = ClothModel.grid(rows, cols, width=size, height=size, plane="xy", mass=0.3,
                            origin=(0.0, 0.0, ground.contact.thickness), colliders=[ground])
    target = bend_into_arch(model.rest_positions, axis=0, up=2)
    objective = (StateKeyframe(steps, x=target, v=np.zeros_like(target),
                               position_weight=weight / model.n, velocity_weight=weight / model.n)
                 + Smoothness(alpha))
    controls = StepForces()
    controls.bind(model.n, 3, steps)
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cloth_arch",
                         controls=controls, adjoint=adjoint, scene={"view": (20, -70)},
                         guess=weight_support(model, controls, steps))
