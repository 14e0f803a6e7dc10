"""What a system is: immutable models whose forces are interaction families of CasADi kernels
(the contract: :mod:`.base`; the families: :mod:`.interaction`)."""
from .base import (BlockJacobians, ForceDerivatives, ForceJacobians, Model, PhysicalReport,
                   Surface)
from .cloth import ClothModel, ClothParams
from .colliders import Capsule, Contact, Plane, Sphere
from .constraints import Attachment
from .flock import FlockModel, FlockParams, wander_forces
from .interaction import Interaction, PairInteraction, ParticleInteraction

__all__ = ["Attachment", "BlockJacobians", "Capsule", "ClothModel", "ClothParams", "Contact",
           "FlockModel", "FlockParams", "ForceDerivatives", "ForceJacobians", "Interaction",
           "Model", "PairInteraction", "ParticleInteraction", "PhysicalReport", "Plane",
           "Sphere", "Surface", "wander_forces"]
