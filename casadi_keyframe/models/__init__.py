"""What a system is: immutable models whose force laws are CasADi kernels."""
from .cloth import ClothModel, ClothParams
from .flock import FlockModel, FlockParams, wander_forces

__all__ = ["ClothModel", "ClothParams", "FlockModel", "FlockParams", "wander_forces"]
