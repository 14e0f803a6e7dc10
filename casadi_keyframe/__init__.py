"""casadi_keyframe: keyframe control of particle systems with the adjoint method.

    prob = casadi_keyframe.load_problem("problems/flock_path.py", agents=50)
    result = casadi_keyframe.solve(prob, method="lbfgsb")
"""
from .controls import InitialVelocity, StepForces
from .gradients import Adjoint, Exact, FiniteDifference
from .loading import list_problems, load_problem
from .objectives import (CenterOfMassKeyframe, Objective, ParticleKeyframe, RegionTarget,
                         Smoothness, StateKeyframe)
from .optimize import Result, solve
from .problem import ControlProblem
from .trajectory import SimulationError, Trajectory

__all__ = [
    "Adjoint", "CenterOfMassKeyframe", "ControlProblem", "Exact", "FiniteDifference",
    "InitialVelocity", "Objective", "ParticleKeyframe", "RegionTarget", "Result",
    "SimulationError", "Smoothness", "StateKeyframe", "StepForces", "Trajectory",
    "list_problems", "load_problem", "solve",
]
