"""Fig. 2: a flock runs a straight course; one agent starts at the back and must finish in front.

The pack (every agent but the runner) follows centre-of-mass keyframes along the course.  At the finish the runner has a
particle keyframe ``lead`` beyond the pack's radius, and the rest of the pack a disc of that
radius around the finish, so "in front" means in front of every other agent.
"""
import numpy as np

from casadi_keyframe.models import FlockParams
from casadi_keyframe.objectives import (CenterOfMassKeyframe, ParticleKeyframe, RegionTarget,
                                       Smoothness)
from casadi_keyframe.scenes.flocks import blob, flock_problem
from casadi_keyframe.shapes import Disc
from casadi_keyframe.views import FlockView

SOLVE = {"method": "lbfgsb", "maxiter": 200}
RANGES = {"agents": "[2, inf)", "steps": "[1, inf)", "dt": "(0, inf)", "seed": "[0, inf)",
          "dim": "[2, 3]", "length": "(0, inf)", "keyframes": "[1, inf)", "lead": "(0, inf)",
          "weight": "[0, inf)", "runner_weight": "[0, inf)", "alpha": "[0, inf)",
          "wander": "[0, inf)", "cutoff": ("smooth", "hard"), "tolerance": "(0, inf)"}


def build(agents: int = 30, steps: int = 160, dt: float = 0.05, seed: int = 0, dim: int = 2,
          length: float = 30.0, keyframes: int = 8, lead: float = 1.5, weight: float = 10.0,
          runner_weight: float = 10.0, alpha: float = 1e-3, wander: float = 0.3,
          cutoff: str = "smooth", tolerance: float = 0.1):
    rng = np.random.default_rng(seed)
    pack_radius = 0.6 * np.sqrt(agents) + 0.5  # room for the pack at its natural spacing
    horizon = steps * dt
    x0 = blob(agents, (0.0, 0.0), 1.0, dim, rng)
    runner = int(np.argmin(x0[:, 0]))  # the agent at the very back of the pack
    speed = length / horizon
    v0 = np.zeros((agents, dim))
    v0[:, 0] = speed
    frames = np.linspace(steps / keyframes, steps, keyframes).round().astype(int)

    def course(frame):
        p = np.zeros(dim)
        p[0] = speed * frame * dt
        return p

    finish = course(steps)
    pack = Disc(finish[:2], pack_radius)
    finish[0] += pack_radius + lead
    others = [i for i in range(agents) if i != runner]
    objective = sum((CenterOfMassKeyframe(int(f), x=course(f), position_weight=weight,
                                          agents=others, tolerance=tolerance) for f in frames),
                    Smoothness(alpha))
    objective = (objective + ParticleKeyframe(steps, [runner], x=[finish],
                                              position_weight=runner_weight,
                                              tolerance=tolerance)
                 + RegionTarget(steps, pack, weight=weight, agents=others))
    return flock_problem(agents=agents, steps=steps, dt=dt, seed=seed, dim=dim,
                         objective=objective, x0=x0, v0=v0, params=FlockParams(cutoff=cutoff),
                         wander=wander, name="flock_race",
                         view=FlockView(highlight=[runner]))
