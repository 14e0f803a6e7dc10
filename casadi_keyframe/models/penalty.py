r"""Collisions as stiff repulsive springs (section 6.1): the penalty law and the family that
applies it between a cloth's particles and one body.

A particle closer than ``thickness`` to a body's surface (signed distance ``phi``) feels a
push along the surface normal ``n`` with penetration ``p = thickness - phi``:

    f = stiffness * ramp(p) * n  -  damping * min(p / width, 1) * ((v - v_body) . n) n

``ramp(p) = p^2 / (2 width)`` for ``0 <= p <= width`` and ``p - width / 2`` beyond, zero for
``p < 0``: the force and its stiffness are continuous when contact starts, so the linearized
implicit step (whose matrix holds the stiffness) does not jump as particles touch.  The
stiffness K the step uses acts along the normal only (the surface's curvature term is left
out, see :func:`penalty_law`), so it is symmetric and negative semi-definite; as for the
springs, the damping's position derivative is left out of K.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from ..kernels import interaction_kernels
from .colliders import Body
from .interaction import ParticleInteraction


def penalty_law(phi, normal, rel_v, gains, x):
    """``(f, K)`` (SX) of a contact with signed distance ``phi`` (a function of ``x``), unit
    ``normal`` and relative velocity ``rel_v``: the force and the stiffness the implicit step
    uses, ``K = -stiffness ramp'(p) normal grad(phi)^T``.

    K leaves out ``ramp(p) d(normal)/dx``, the surface's curvature: for a sphere or capsule
    it pushes particles apart sideways, and with it the step matrix loses positive
    definiteness (as for compressed springs, see :func:`.springs.spring_law`).
    """
    k, c, h, s = (gains[i] for i in range(4))
    p = h - phi
    ramp = ca.if_else(p <= 0, 0, ca.if_else(p <= s, p ** 2 / (2 * s), p - s / 2))
    active = ca.fmin(ca.fmax(p / s, 0), 1)  # ramp'(p)
    force = k * ramp * normal - c * active * ca.dot(rel_v, normal) * normal
    return force, -k * active * ca.mtimes(normal, ca.jacobian(phi, x))


@functools.lru_cache(maxsize=None)
def body_kernels(body_type: type) -> dict[str, ca.Function]:
    """The penalty kernels of a body class ``(x, v, *geometry, gains) -> ...`` (see
    :func:`~casadi_keyframe.kernels.interaction_kernels`)."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    geo = {key: ca.SX.sym(key, size) for key, size in body_type.GEOMETRY.items()}
    gains = ca.SX.sym("gains", 4)
    phi, normal, v_body = body_type.surface(x, **geo)
    name = f"{body_type.kind}_contact"
    return interaction_kernels(name, x, v, [*geo.values(), gains],
                               *penalty_law(phi, normal, v - v_body, gains, x))


class BodyPenalty(ParticleInteraction):
    """The penalty contact of every particle with one :class:`~.colliders.Body`."""

    name = "body penalty"
    role = "contact"

    def __init__(self, body: Body, n: int, jit: bool | None = None):
        if not isinstance(body, Body):
            raise ValueError(f"colliders must be Plane, Sphere or Capsule bodies, got {body!r}")
        super().__init__(body_kernels(type(body)), n, jit)
        self.body = body

    def columns(self, t):
        """The geometry at time t and the contact gains, one row per particle."""
        columns = [np.broadcast_to(g, (self.n, np.size(g))) for g in self.body.geometry(t)]
        return columns + [np.broadcast_to(self.body.contact.gains, (self.n, 4))]

    def parameters(self, t):
        return self.body.parameters(t)

    def symbolic_columns(self, S):
        parts, at = [], 0
        for size in self.body.GEOMETRY.values():
            parts.append(S[at:at + size])
            at += size
        return parts + [ca.DM(self.body.contact.gains)]
