"""Time-stepping schemes, each with its adjoint step beside it."""
from .linearized_backward_euler import LinearizedBackwardEuler
from .symplectic_euler import SymplecticEuler

__all__ = ["LinearizedBackwardEuler", "SymplecticEuler"]
