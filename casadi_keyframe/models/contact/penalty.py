r"""Collisions as stiff repulsive springs (section 6.1): the penalty law and its two
families, between a cloth's particles and one body (:class:`BodyPenalty`) and between
particles of the cloth itself (:class:`SelfPenalty`).

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
from scipy.spatial import cKDTree

from ...kernels import interaction_kernels
from .colliders import Body, Contact
from ..interaction import PairInteraction, ParticleInteraction


def penalty_law(phi, normal, rel_v, gains, x):
    """``(f, K)`` (SX) of a contact with signed distance ``phi`` (a function of ``x``), unit
    ``normal`` and relative velocity ``rel_v``: the force and the stiffness the implicit step
    uses, ``K = -stiffness ramp'(p) normal grad(phi)^T``.

    K leaves out ``ramp(p) d(normal)/dx``, the surface's curvature: for a sphere or capsule
    it pushes particles apart sideways, and with it the step matrix loses positive
    definiteness (as for compressed springs, see :func:`..springs.spring_law`).
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
    name = f"{body_type.kind}_penalty"
    return interaction_kernels(name, x, v, [*geo.values(), gains],
                               *penalty_law(phi, normal, v - v_body, gains, x))


class BodyPenalty(ParticleInteraction):
    """The penalty contact of every particle with one :class:`~.colliders.Body`.  On a body
    whose geometry differs per point (a mesh: each particle's closest feature), a step
    decides each particle's feature at its start, and the symbolic step takes them as its
    decisions."""

    name = "body penalty"
    role = "contact"

    def __init__(self, body: Body, n: int, jit: bool | None = None):
        if not isinstance(body, Body):
            raise ValueError(f"colliders must be bodies (Plane, Sphere, Capsule, MeshBody), "
                             f"got {body!r}")
        super().__init__(body_kernels(type(body)), n, jit)
        self.body = body
        self.width = sum(body.GEOMETRY.values())

    def columns(self, t):
        """The geometry at time t and the contact gains, one row per particle."""
        columns = [np.broadcast_to(g, (self.n, np.size(g))) for g in self.body.geometry(t)]
        return columns + [np.broadcast_to(self.body.contact.gains, (self.n, 4))]

    def columns_at(self, x, t, found):
        """:meth:`columns`; on a mesh, each particle's feature (the step's, decided at x)."""
        if not self.body.local:
            return self.columns(t)
        same = found is not None and (found[0] is x or np.array_equal(found[0], x))
        rows = found[1] if same else self.body.local_geometry(x, t)
        return [*rows, np.broadcast_to(self.body.contact.gains, (self.n, 4))]

    def decide(self, step, carried):
        """On a mesh: ``(x, rows)``, each particle's feature at the step's start (exact
        within the body's reach: beyond it the springs do not act)."""
        if not self.body.local:
            return None
        reach = self.body.reach(step.v, step.t, step.dt)
        return step.x, self.body.local_geometry(step.x, step.t, reach)

    def decision_parameters(self, found, t, dt):
        """On a mesh, the rows of :meth:`decide` (one column of the symbolic step's per
        particle); else none."""
        if not self.body.local:
            return np.zeros(0)
        if found is None:
            return np.zeros(self.n * self.width)
        return np.hstack(found[1]).ravel()

    def parameters(self, t):
        return self.body.parameters(t)

    def symbolic_columns(self, S, decisions=None):
        if self.body.local:
            if decisions is None:
                raise ValueError(f"the symbolic step of penalty contact on a {self.body.kind} "
                                 "body needs the step's decisions (each particle's feature): "
                                 "its CasADi route is LinearizedBackwardEuler's")
            G = ca.reshape(decisions, self.width, self.n)
        else:
            G = S
        parts, at = [], 0
        for size in self.body.GEOMETRY.values():
            parts.append(G[at:at + size, :])
            at += size
        return parts + [ca.DM(self.body.contact.gains)]


@functools.lru_cache(maxsize=None)
def self_penalty_kernels() -> dict[str, ca.Function]:
    """The penalty law between particles i and j, ``(d = x_j - x_i, dv = v_j - v_i, gains)
    -> f_i``."""
    d, dv, gains = ca.SX.sym("d", 3), ca.SX.sym("dv", 3), ca.SX.sym("gains", 4)
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    # i is pushed along -d/r, away from j; the velocity of i relative to j is -dv
    return interaction_kernels("self_penalty", d, dv, [gains],
                               *penalty_law(r, -d / r, -dv, gains, d))


class SelfPenalty(PairInteraction):
    """Self-contact: repulsion between cloth particles nearer than ``contact.thickness`` and
    not joined by a spring; ``excluded`` is the (P, 2) array of joined pairs.  The pairs are
    found with a k-d tree once per state (:meth:`find`)."""

    name = "self-contact"
    role = "contact"
    fixed_pairs = False

    def __init__(self, contact: Contact, excluded: np.ndarray, n: int,
                 jit: bool | None = None):
        super().__init__(self_penalty_kernels(), n, jit)
        self.contact = contact
        e = np.sort(np.asarray(excluded, dtype=np.int64), axis=1)
        self._excluded = np.unique(e[:, 0] * n + e[:, 1])

    def find(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays ``(i, j)``, i < j, of unjoined particles within the thickness."""
        found = cKDTree(x).query_pairs(self.contact.thickness, output_type="ndarray")
        if found.size == 0:
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        found = np.sort(found, axis=1)
        keep = ~np.isin(found[:, 0].astype(np.int64) * self.n + found[:, 1], self._excluded)
        return found[keep, 0].astype(np.intp), found[keep, 1].astype(np.intp)

    def pairs(self, found):
        return None if found is None or found[0].size == 0 else found

    def pair_parameters(self, i, j, found=None):
        return [np.broadcast_to(self.contact.gains, (i.size, 4))]

    def all_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every unjoined pair (for the symbolic, small-system route)."""
        i, j = np.triu_indices(self.n, 1)
        keep = ~np.isin(i.astype(np.int64) * self.n + j, self._excluded)
        return i[keep], j[keep]
