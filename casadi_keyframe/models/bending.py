r"""Dihedral bending: the two triangles of each interior edge resist a change of the angle
between them (discrete shells, Grinspun et al. 2003; the hinge of Bridson et al. 2003).

A hinge ``(x0, x1, x2, x3)`` is the edge ``e = x1 - x0`` of the triangles ``(x0, x1, x2)``
and ``(x0, x3, x1)``, normals ``n1 = e x (x2 - x0)``, ``n2 = (x3 - x0) x e``; its angle is
``theta = atan2((n1 x n2) . e / |e|, n1 . n2)``, 0 when flat, signed by the fold.  The
energy ``E = k w (theta - rest)^2 / 2`` with the rest shape's angle and weight
``w = 3 |e|^2 / (A1 + A2)`` (so a sheet's stiffness does not depend on its mesh), and
damping ``c w`` on the angle's rate, give

    f = -w (k (theta - rest) + c grad(theta) . v) grad(theta)

which sums to zero.  ``df/dx = -k w grad grad^T - k w (theta - rest) hess(theta)``: the
second term (the angle's curvature) is indefinite, so the step's K keeps the first only
(Gauss-Newton, as the springs clamp their transverse term): K and ``D = -c w grad grad^T``
are symmetric and negative semi-definite, and the step matrix stays positive definite.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from ..kernels import interaction_kernels
from .interaction import StencilInteraction
from .topology import mesh_hinges


def hinge_angle(x):
    """The signed angle of the hinge of the stacked positions ``x`` (12, SX)."""
    x0, x1, x2, x3 = (x[3 * a:3 * a + 3] for a in range(4))
    e = x1 - x0
    n1, n2 = ca.cross(e, x2 - x0), ca.cross(x3 - x0, e)
    return ca.atan2(ca.dot(ca.cross(n1, n2), e) / ca.norm_2(e), ca.dot(n1, n2))


def hinge_law(x, v, rest, k, c):
    """``(f, K)`` of one hinge (module docstring), ``k`` and ``c`` already times w."""
    theta = hinge_angle(x)
    grad = ca.gradient(theta, x)
    force = -(k * (theta - rest) + c * ca.dot(grad, v)) * grad
    return force, -k * ca.mtimes(grad, grad.T)


@functools.lru_cache(maxsize=None)
def hinge_kernels() -> dict[str, ca.Function]:
    """``(x (12), v (12), rest, k w, c w) -> f (12)`` and its derivative kernels
    (:func:`~casadi_keyframe.kernels.interaction_kernels`), K from :func:`hinge_law`."""
    x, v = ca.SX.sym("x", 12), ca.SX.sym("v", 12)
    scalars = [ca.SX.sym(name) for name in ("rest", "k", "c")]
    kernels = interaction_kernels("dihedral_bending", x, v, scalars, *hinge_law(x, v, *scalars))
    return {**kernels, "angle": ca.Function("hinge_angle", [x], [hinge_angle(x)])}


class DihedralBending(StencilInteraction):
    """Dihedral bending of a cloth of ``rest_positions`` and triangle ``faces``:
    ``stiffness`` k (N m: energy per squared radian of a hinge of weight 1), ``damping`` c
    (N m s); the rest angles and weights are the rest shape's.  Give it to a cloth as one
    family: ``ClothModel.grid(..., families=[DihedralBending.of(sheet, stiffness=...)])``."""

    name = "dihedral bending"
    role = "internal"

    def __init__(self, rest_positions, faces, *, stiffness: float, damping: float = 0.0,
                 jit: bool | None = None):
        for label, value in (("stiffness", stiffness), ("damping", damping)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"DihedralBending {label} must be non-negative and finite, "
                                 f"got {value}")
        rest = np.asarray(rest_positions, dtype=float)
        _, hinges = mesh_hinges(faces)
        if not hinges.size:
            raise ValueError("DihedralBending needs a mesh with an interior edge (two "
                             "triangles sharing an edge); these faces have none")
        super().__init__(hinge_kernels(), hinges, len(rest), jit)
        x0, x1, x2, x3 = (rest[hinges[:, a]] for a in range(4))
        e = x1 - x0
        areas = (np.linalg.norm(np.cross(e, x2 - x0), axis=1)
                 + np.linalg.norm(np.cross(x3 - x0, e), axis=1)) / 2
        if not np.all(areas > 0):
            raise ValueError("DihedralBending: a hinge's triangles have no area; remove the "
                             "degenerate faces")
        weight = 3 * np.einsum("ha,ha->h", e, e) / areas
        self.parameters_per_hinge = (self.angles(rest)[:, None], stiffness * weight[:, None],
                                     damping * weight[:, None])
        for a in self.parameters_per_hinge:
            a.flags.writeable = False

    @classmethod
    def of(cls, cloth, *, stiffness: float, damping: float = 0.0) -> "DihedralBending":
        """The bending of ``cloth``'s rest shape (its rest positions, faces and ``jit``)."""
        return cls(cloth.rest_positions, cloth.faces, stiffness=stiffness, damping=damping,
                   jit=cloth.jit)

    def stencil_parameters(self):
        return list(self.parameters_per_hinge)

    def angles(self, x: np.ndarray) -> np.ndarray:
        """Every hinge's angle (rad) at positions ``x`` ``(n, 3)``."""
        stacked = np.asarray(x, dtype=float)[self.stencils].reshape(len(self.stencils), 12)
        return np.asarray(self.kernels["angle"].map(len(self.stencils))(stacked.T)).ravel()
