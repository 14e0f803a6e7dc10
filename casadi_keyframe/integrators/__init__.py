"""Time-stepping schemes, each with its adjoint step beside it."""
from .backward_euler import BackwardEuler
from .linearized_backward_euler import LinearizedBackwardEuler
from .symplectic_euler import SymplecticEuler

__all__ = ["BackwardEuler", "LinearizedBackwardEuler", "SymplecticEuler"]
