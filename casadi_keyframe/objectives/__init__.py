"""Objective terms, by kind; they add up with ``+`` into an :class:`Objective`.

* :mod:`.terms`: the sum and the three kinds of term (state, control, trajectory);
* :mod:`.keyframes`: state and centre-of-mass keyframes; :mod:`.regions`: region targets;
  :mod:`.mesh`: a keyframe given as a mesh;
* :mod:`.effort`: the control effort; :mod:`.strain`: the soft strain limit;
* :mod:`.tolerances`: when a keyframe counts as met, and a motion as physical;
* :mod:`.markers`: what a keyframe term shows; :mod:`.keyframe_goal`: how the goal judges it;
* :mod:`.paths`: paths through the keyframes' targets (guesses and starts without a controller).
"""
from .effort import Smoothness
from .keyframes import CenterOfMassKeyframe, ParticleKeyframe, StateKeyframe
from .mesh import MeshKeyframe
from .regions import RegionTarget
from .strain import StrainLimit
from .terms import ControlTerm, Objective, StateTerm, TrajectoryTerm
from .tolerances import PhysicalLimits

__all__ = ["CenterOfMassKeyframe", "ControlTerm", "MeshKeyframe", "Objective",
           "ParticleKeyframe", "PhysicalLimits", "RegionTarget", "Smoothness", "StateKeyframe", "StateTerm",
           "StrainLimit", "TrajectoryTerm"]
