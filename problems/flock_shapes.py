"""Fig. 1 (its flock half): 200 agents form a square, then a cross, by region keyframes."""
import numpy as np

from casadi_keyframe.models import FlockParams
from casadi_keyframe.objectives import RegionTarget, Smoothness
from casadi_keyframe.scenes.flocks import blob, flock_problem
from casadi_keyframe.shapes import cross, square

SOLVE = {"method": "lbfgsb", "maxiter": 300}
RANGES = {"agents": "[1, inf)", "steps": "[2, inf)", "dt": "(0, inf)", "seed": "[0, inf)",
          "dim": "[2, 3]", "spacing": "(0, inf)", "weight": "[0, inf)", "margin": "[0, inf)",
          "alpha": "[0, inf)", "wander": "[0, inf)", "cutoff": ("smooth", "hard")}


def build(agents: int = 200, steps: int = 200, dt: float = 0.05, seed: int = 0, dim: int = 2,
          spacing: float = 1.0, weight: float = 10.0, margin: float = 0.2, alpha: float = 1e-3,
          wander: float = 0.3, cutoff: str = "smooth"):
    rng = np.random.default_rng(seed)
    area = agents * spacing ** 2  # room for every agent at the flock's natural spacing
    side = np.sqrt(area)
    width = _cross_width(area)
    first, second = steps // 2, steps
    sq = square((12.0, 6.0), side)
    cr = cross((26.0, -6.0), 3 * width, width)
    x0 = blob(agents, (0.0, 0.0), 1.0, dim, rng)
    v0 = np.zeros((agents, dim))
    v0[:, 0] = 12.0 / (first * dt)
    objective = (RegionTarget(first, sq, weight=weight, margin=margin)
                 + RegionTarget(second, cr, weight=weight, margin=margin) + Smoothness(alpha))
    return flock_problem(agents=agents, steps=steps, dt=dt, seed=seed, dim=dim,
                         objective=objective, x0=x0, v0=v0, params=FlockParams(cutoff=cutoff),
                         wander=wander, name="flock_shapes")


def _cross_width(area: float) -> float:
    """Bar width of a cross whose bars are three widths long and whose area is ``area``."""
    return np.sqrt(area / 5.0)  # a 3w x 3w cross with w-wide bars covers 5 w^2
