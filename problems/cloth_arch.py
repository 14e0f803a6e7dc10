"""Fig. 1 (its cloth half): a sheet lying on the ground bends up into an arch and holds it.

Per-step control forces on every particle; the keyframe at the last frame asks for the sheet
rolled into a half cylinder of the same arc length, its two ends on the ground, at rest.  The
optimizer starts from forces that carry the sheet's weight: from zero forces a sheet resting
on the ground must first outweigh the contact before it moves at all, so its gradient there
is almost zero.  The default gradient is the exact hand adjoint of the linearized step: the
sheet lies in stiff contact and bends through compressed springs, where the paper's swapped
adjoint is poor (``--gradient swapped`` runs it).  ``friction`` is the ground's Coulomb
coefficient (0: frictionless).  Coarse to fine did no better than the
direct solve here, so ``SOLVE`` does not ask for it.  Measurements behind these choices:
``docs/problem_notes.md``.
"""
import numpy as np

from casadi_keyframe.controls import StepForces
from casadi_keyframe.models import COLLISIONS, DEFAULT_COLLISION, ClothModel
from casadi_keyframe.models.contact.colliders import Contact, Plane
from casadi_keyframe.objectives import StateKeyframe, Smoothness, StrainLimit
from casadi_keyframe.scenes.cloths import bend_into_arch, cloth_problem, weight_support
from casadi_keyframe.views import ClothView

SOLVE = {"method": "lbfgsb", "maxiter": 150, "gradient": "adjoint"}
RANGES = {"rows": "[2, inf)", "cols": "[2, inf)", "steps": "[1, inf)", "dt": "(0, inf)",
          "size": "(0, inf)", "weight": "[0, inf)", "alpha": "[0, inf)",
          "strain_limit": "[1, inf)", "strain_weight": "[0, inf)",
          "collision": COLLISIONS, "friction": "[0, inf)"}


def build(rows: int = 15, cols: int = 15, steps: int = 60, dt: float = 1 / 60,
          size: float = 1.0, weight: float = 100.0, alpha: float = 1e-4,
          strain_limit: float = 1.2, strain_weight: float = 1e3,
          collision: str = DEFAULT_COLLISION, friction: float = 0.0):
    ground = Plane((0.0, 0.0, 0.0), contact=Contact(friction=friction))
    model = ClothModel.grid(rows, cols, width=size, height=size, plane="xy", mass=0.3,
                            origin=(0.0, 0.0, ground.contact.thickness), colliders=[ground],
                            collision=collision)
    target = bend_into_arch(model.rest_positions, axis=0, up=2)
    objective = (StateKeyframe(steps, x=target, v=np.zeros_like(target),
                               position_weight=weight / model.n, velocity_weight=weight / model.n,
                               tolerance=(0.01, 0.1))
                 + Smoothness(alpha) + StrainLimit(strain_limit, strain_weight))
    controls = StepForces()
    controls.bind(model.n, 3, steps)
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cloth_arch",
                         controls=controls, view=ClothView(camera=(20, -70)),
                         guess=weight_support(model, controls, steps))
