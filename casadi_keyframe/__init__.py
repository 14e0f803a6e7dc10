"""casadi_keyframe: keyframe control of particle systems with the adjoint method.

    prob = casadi_keyframe.load_problem("problems/flock_path.py", agents=50)
    result = casadi_keyframe.solve(prob, method="lbfgsb")
"""
from .adjoints import Adjoint, CasADiReverse, Exact, FiniteDifference, Swapped
from .controls import InitialVelocity, StepForces
from .loading import list_problems, load_problem
from .objectives import (CenterOfMassKeyframe, Objective, ParticleKeyframe, RegionTarget,
                         Smoothness, StateKeyframe, StrainLimit)
from .optimize import Result, solve
from .problem import ControlProblem
from .simulate import backward, simulate
from .state import SimulationError, State, Trajectory

__all__ = [
    "Adjoint", "CasADiReverse", "CenterOfMassKeyframe", "ControlProblem", "Exact",
    "FiniteDifference", "InitialVelocity", "Objective", "ParticleKeyframe", "RegionTarget",
    "Result", "SimulationError", "Smoothness", "State", "StateKeyframe", "StepForces",
    "StrainLimit",
    "Swapped", "Trajectory", "backward", "list_problems", "load_problem", "simulate", "solve",
]
