"""Fig. 3: a flock of 100 agents follows a curved path set by centre-of-mass keyframes."""
from casadi_keyframe.scenes.flock_path import flock_path_problem

SOLVE = {"method": "lbfgsb", "maxiter": 200}
RANGES = {"agents": "[1, inf)", "steps": "[1, inf)", "dt": "(0, inf)", "seed": "[0, inf)",
          "dim": "[2, 3]", "keyframes": "[1, inf)", "weight": "[0, inf)", "alpha": "[0, inf)",
          "wander": "[0, inf)", "cutoff": ("smooth", "hard"), "tolerance": "(0, inf)"}

build = flock_path_problem  # the figure's settings are its defaults; the studies use it too
