"""Fig. 1 (its cloth half): a sheet lying on the ground bends up into an arch and holds it.

Per-step control forces on every particle; the keyframe at the last frame asks for the sheet
rolled into a half cylinder of the same arc length, its two ends on the ground, at rest.  The
optimizer starts from forces that carry the sheet's weight: from zero forces a sheet resting
on the ground must first outweigh the contact before it moves at all, so its gradient there
is almost zero (measured: L-BFGS-B stalls with the sheet flat).

The default gradient is the exact hand adjoint of the linearized step.  The sheet lies in
stiff contact with the ground and bends through compressed springs, where the paper's
swapped adjoint is poor (6 x 6 sheet, 40 steps: cosine to the exact gradient 0.68 at random
0.01 N perturbations of the start, 0.46 at 0.03 N; L-BFGS-B stops with the line search
failing at an 8.0 cm root-mean-square miss, against 1.3 cm with the exact adjoint).
``--gradient swapped`` runs the paper's method.

At the default 15 x 15 (``benchmarks/cloth_figures.py``, one BLAS thread; rms miss over the
225 particles, largest spring stretch, iterations, CPU seconds):

    =================  ========  =======  ==========  =====
    route              rms miss  stretch  iterations  CPU s
    =================  ========  =======  ==========  =====
    exact adjoint      5.9 mm    1.01     58          38
    swapped (paper's)  44.8 mm   1.01     38          27
    =================  ========  =======  ==========  =====

Both stop on L-BFGS-B's relative-reduction test.  Coarse to fine (8 x 8 first) ended
7.5 mm off: no better than the direct solve here, so ``SOLVE`` does not ask for it.
"""
import numpy as np

from casadi_keyframe.controls import StepForces
from casadi_keyframe.models import ClothModel
from casadi_keyframe.models.colliders import Plane
from casadi_keyframe.objectives import StateKeyframe, Smoothness, StrainLimit
from casadi_keyframe.scenes.cloths import bend_into_arch, cloth_problem, weight_support
from casadi_keyframe.views import ClothView

SOLVE = {"method": "lbfgsb", "maxiter": 150, "gradient": "adjoint"}
RANGES = {"rows": "[2, inf)", "cols": "[2, inf)", "steps": "[1, inf)", "dt": "(0, inf)",
          "size": "(0, inf)", "weight": "[0, inf)", "alpha": "[0, inf)",
          "strain_limit": "[1, inf)", "strain_weight": "[0, inf)"}


def build(rows: int = 15, cols: int = 15, steps: int = 60, dt: float = 1 / 60,
          size: float = 1.0, weight: float = 100.0, alpha: float = 1e-4,
          strain_limit: float = 1.2, strain_weight: float = 1e3):
    ground = Plane((0.0, 0.0, 0.0))
    model = ClothModel.grid(rows, cols, width=size, height=size, plane="xy", mass=0.3,
                            origin=(0.0, 0.0, ground.contact.thickness), colliders=[ground])
    target = bend_into_arch(model.rest_positions, axis=0, up=2)
    objective = (StateKeyframe(steps, x=target, v=np.zeros_like(target),
                               position_weight=weight / model.n, velocity_weight=weight / model.n)
                 + Smoothness(alpha) + StrainLimit(strain_limit, strain_weight))
    controls = StepForces()
    controls.bind(model.n, 3, steps)
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective, name="cloth_arch",
                         controls=controls, view=ClothView(camera=(20, -70)),
                         guess=weight_support(model, controls, steps))
