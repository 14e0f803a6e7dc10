"""What a system is: immutable models whose forces are interaction families of CasADi kernels
(the contract: :mod:`.base`; the families: :mod:`.interaction`)."""
from .base import (BlockJacobians, ForceDerivatives, ForceJacobians, Model, PhysicalReport,
                   StepHold, Surface)
from .cloth import ClothModel, ClothParams
from .contact.colliders import Capsule, Contact, MeshBody, Plane, Sphere
from .contact.collisions import COLLISIONS, DEFAULT_COLLISION
from .contact.friction import Coulomb
from .contact.tangential import TangentialLaw
from .constraints import Attachment
from .flock import FlockModel, FlockParams, wander_forces
from .interaction import Interaction, PairInteraction, ParticleInteraction, StencilInteraction

__all__ = ["Attachment", "BlockJacobians", "COLLISIONS", "Capsule", "ClothModel", "ClothParams",
           "Contact", "Coulomb", "DEFAULT_COLLISION", "FlockModel", "FlockParams", "ForceDerivatives",
           "ForceJacobians", "Interaction", "MeshBody", "Model", "PairInteraction", "ParticleInteraction",
           "PhysicalReport", "Plane", "Sphere", "StencilInteraction", "StepHold", "Surface",
           "TangentialLaw", "wander_forces"]
