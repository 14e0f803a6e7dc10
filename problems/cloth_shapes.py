"""Fig. 4: a piece of cloth hanging from its top corners swings into shapes given as target
positions: forward, into a wave, then back.

Per-step control forces on the free particles; each keyframe gives every particle's position.
Passive, the sheet hangs exactly in its plane (compressed across its width as it sags), so
the solve starts on a flat state; the cloth model's Choi-Ko law keeps the gradient there
meaningful (see :mod:`casadi_keyframe.models.springs`).  The wave keeps each row's length
(:func:`~casadi_keyframe.scenes.cloths.wave_across`), so a physical motion can reach it.
``SOLVE`` first solves a 6 x 6 sheet of the same cloth (``resolutions``), whose forces,
carried to the finer mesh, start its search.  Measurements behind these choices:
``docs/problem_notes.md``.
"""
import numpy as np

from casadi_keyframe.models import ClothModel
from casadi_keyframe.objectives import StateKeyframe, Smoothness, StrainLimit
from casadi_keyframe.scenes.cloths import cloth_problem, rotate_about, wave_across
from casadi_keyframe.views import ClothView

SOLVE = {"method": "lbfgsb", "maxiter": 150, "gradient": "adjoint",
         "resolutions": [{"rows": 6, "cols": 6}]}
RANGES = {"rows": "[2, inf)", "cols": "[2, inf)", "steps": "[1, inf)", "dt": "(0, inf)",
          "size": "(0, inf)", "weight": "[0, inf)", "alpha": "[0, inf)",
          "strain_limit": "[1, inf)", "strain_weight": "[0, inf)", "tolerance": "(0, inf)"}


def shapes(rest: np.ndarray, size: float) -> list[np.ndarray]:
    """Target positions: swung forward 60 degrees, a wave across (one sine period, 0.2 size
    deep at the bottom edge, none at the top; each row keeps its length), swung back 40
    degrees."""
    top = rest[:, 2].max()
    pivot, axis = (0.0, 0.0, top), (1.0, 0.0, 0.0)
    forward = rotate_about(rest, pivot, axis, np.radians(60))
    wave = wave_across(rest, 0.2 * (top - rest[:, 2]), along=0, out=1)
    back = rotate_about(rest, pivot, axis, np.radians(-40))
    return [forward, wave, back]


def build(rows: int = 12, cols: int = 12, steps: int = 120, dt: float = 1 / 60,
          size: float = 1.0, weight: float = 100.0, alpha: float = 1e-4,
          strain_limit: float = 1.2, strain_weight: float = 1e3, tolerance: float = 0.02):
    model = ClothModel.grid(rows, cols, width=size, height=size, mass=0.3,
                            pinned=[0, cols - 1])
    frames = np.linspace(steps / 3, steps, 3).round().astype(int)
    objective = sum((StateKeyframe(int(f), x=x, position_weight=weight / model.n,
                                   tolerance=tolerance)
                     for f, x in zip(frames, shapes(model.rest_positions, size))),
                    Smoothness(alpha) + StrainLimit(strain_limit, strain_weight))
    return cloth_problem(model=model, steps=steps, dt=dt, objective=objective,
                         name="cloth_shapes", view=ClothView(camera=(15, -30)))
