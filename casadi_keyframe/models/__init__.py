"""What a system is: immutable models whose force laws are CasADi kernels."""
from .flock import FlockModel, FlockParams, wander_forces

__all__ = ["FlockModel", "FlockParams", "wander_forces"]
