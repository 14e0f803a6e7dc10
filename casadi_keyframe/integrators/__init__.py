"""Time-stepping schemes, each with its adjoint step beside it."""
from .symplectic_euler import SymplecticEuler

__all__ = ["SymplecticEuler"]
