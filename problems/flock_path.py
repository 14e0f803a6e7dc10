"""Fig. 3: a flock of 100 agents follows a curved path set by centre-of-mass keyframes."""
import numpy as np

from casadi_keyframe.objectives import CenterOfMassKeyframe, Smoothness
from casadi_keyframe.scenes.flocks import blob, flock_problem

SOLVE = {"method": "lbfgsb", "maxiter": 200}
RANGES = {"agents": "[1, inf)", "steps": "[1, inf)", "dt": "(0, inf)", "seed": "[0, inf)",
          "dim": "[2, 3]", "keyframes": "[1, inf)", "weight": "[0, inf)", "alpha": "[0, inf)",
          "wander": "[0, inf)", "cutoff": ("smooth", "hard")}


def path_point(s: float) -> np.ndarray:
    """The S-shaped path at arc parameter s in [0, 1]."""
    return np.array([40.0 * s, 8.0 * np.sin(2 * np.pi * s)])


def build(agents: int = 100, steps: int = 200, dt: float = 0.05, seed: int = 0, dim: int = 2,
          keyframes: int = 8, weight: float = 10.0, alpha: float = 1e-3, wander: float = 0.3,
          cutoff: str = "smooth"):
    from casadi_keyframe.models import FlockParams
    rng = np.random.default_rng(seed)
    horizon = steps * dt
    frames = np.linspace(steps / keyframes, steps, keyframes).round().astype(int)
    start = path_point(0.0)
    v_start = (path_point(1e-3) - start) / 1e-3 / horizon
    objective = sum((CenterOfMassKeyframe(int(f), x=_pad(path_point(f / steps), dim),
                                          position_weight=weight) for f in frames),
                    Smoothness(alpha))
    v0 = np.zeros((agents, dim))
    v0[:, :2] = 0.5 * v_start
    return flock_problem(agents=agents, steps=steps, dt=dt, seed=seed, dim=dim,
                         objective=objective, x0=blob(agents, start, 1.0, dim, rng), v0=v0,
                         params=FlockParams(cutoff=cutoff), wander=wander, name="flock_path",
                         scene={"path": np.array([path_point(s) for s in np.linspace(0, 1, 100)])})


def _pad(p, dim):
    out = np.zeros(dim)
    out[:2] = p
    return out
