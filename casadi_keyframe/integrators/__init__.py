"""Time-stepping schemes: one file each, its step, backward step and tangent step side by side
(the contract is in :mod:`.base`)."""
from .backward_euler import BackwardEuler
from .base import Integrator, Workspace
from .linearized_backward_euler import LinearizedBackwardEuler
from .symplectic_euler import SymplecticEuler

__all__ = ["BackwardEuler", "Integrator", "LinearizedBackwardEuler", "SymplecticEuler",
           "Workspace"]
