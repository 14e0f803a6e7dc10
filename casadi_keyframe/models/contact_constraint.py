r"""Contact that holds: a particle touching a body has its velocity along the body's normal
prescribed inside the implicit step, as Baraff and Witkin treat contact (the filter of their
modified CG), instead of a stiff spring that sees the body only once the particle is inside.

For the step from t, ``phi_0`` and ``phi_1`` are a particle's signed distances (negative
inside) to the body's surface where the body is at t and at t + dt, ``n`` the outward unit
normal of the latter at the particle: ``phi_0 - phi_1`` is how far the body comes towards
the particle within the step.  In contact, the step ends with

    n . v+ = c = (phi_0 - phi_1) / dt + (thickness - phi_0) / dt          (phi_0 >= thickness)
    n . v+ = c = (phi_0 - phi_1) / dt + beta (thickness - phi_0) / dt     (phi_0 < thickness)

and a particle is in contact when it would end the step within the layer moving as it
does, ``phi_1 + dt n . v <= thickness + tolerance`` (i.e. ``dt (n . v - c) <= tolerance``
for an arriving particle).

so an arriving particle ends the step on the layer's surface (exactly for a plane, outside
it for a sphere or a capsule, whose distance is convex), and one found inside the layer is
moved a fraction ``beta`` (:data:`CORRECTION`) of the way back per step, so that it stays in
contact instead of leaving with the correction's speed.  Its tangential velocity stays free
(no friction).  A particle the constraint held
towards the body in the previous step (a negative impulse: the contact pulled) is released,
and stays released while it moves away.  Each particle takes the contact of the body it
would reach deepest.

The step with the contacts held solves ``S (A dv - b) = 0`` and ``P (dv - z) = 0``, with
``P = n n^T`` on each contact particle, ``S = I - P`` and ``z = n (c - n . v)``: its exact
derivative, with the contacts held, is the filter's projection plus the derivatives of the
normal and of the target, which :class:`BodyConstraint`'s kernels give per contact
(``vjp``: the gradients of ``-lam . n (n . q) + nu . z`` in x and v; ``jvp``: the
derivative of ``-n (n . q) + nbar (nbar . z)`` with ``nbar`` held).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..kernels import MappedKernel
from .colliders import Body, signed_distances
from .base import ContactConstraints
from .interaction import FamilyBlocks, Interaction

TOLERANCE = 0.25  # of the thickness: a particle this close to the layer's surface touches it
OVERSHOOT = 0.1  # of the thickness: a step that leaves a particle this far past it is redone
CORRECTION = 0.5  # of a particle's depth in the layer undone per step (beta)


@functools.lru_cache(maxsize=None)
def constraint_kernels(body_type: type) -> dict[str, ca.Function]:
    """Per particle ``(x, v, *geometry at t, *geometry at t + dt, h, dt)``:
    ``constraint -> (phi_0, n, c)``, ``vjp(..., lam, q, nu) -> (gx, gv)`` and ``jvp(..., q,
    nbar, dx, dv) -> d`` (module docstring)."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    start = {key: ca.SX.sym(f"{key}_0", size) for key, size in body_type.GEOMETRY.items()}
    end = {key: ca.SX.sym(f"{key}_1", size) for key, size in body_type.GEOMETRY.items()}
    h, dt = ca.SX.sym("h"), ca.SX.sym("dt")
    phi, _, _ = body_type.surface(x, **start)
    phi_end, n, _ = body_type.surface(x, **end)
    c = (phi - phi_end) / dt + ca.if_else(phi >= h, 1.0, CORRECTION) * (h - phi) / dt
    z = n * (c - ca.dot(n, v))
    args = [x, v, *start.values(), *end.values(), h, dt]
    lam, q, nu, nbar = (ca.SX.sym(s, 3) for s in ("lam", "q", "nu", "nbar"))
    dx, dv = ca.SX.sym("dx", 3), ca.SX.sym("dv", 3)
    scalar = -ca.dot(lam, n) * ca.dot(n, q) + ca.dot(nu, z)
    vector = -n * ca.dot(n, q) + nbar * ca.dot(nbar, z)
    name = f"{body_type.kind}_constraint"
    return {
        "constraint": ca.Function(name, args, [phi, n, c]),
        "vjp": ca.Function(f"{name}_vjp", args + [lam, q, nu],
                           [ca.gradient(scalar, x), ca.gradient(scalar, v)]),
        "jvp": ca.Function(f"{name}_jvp", args + [q, nbar, dx, dv],
                           [ca.jtimes(vector, ca.vertcat(x, v), ca.vertcat(dx, dv))]),
    }


@dataclass(frozen=True)
class Contacts:
    """The contacts a step holds: ``particles`` ``(k,)`` (sorted), the ``body`` each touches
    (index into the model's constraint families), their unit ``normals`` ``(k, 3)`` and
    target normal velocities ``targets`` ``(k,)`` at the step's start; after the step,
    ``impulse`` ``(k,)``, the constraint's impulse along the normal (negative: it pulled),
    and ``released`` ``(n,)``, the particles let go (see the module docstring)."""

    particles: np.ndarray
    body: np.ndarray
    normals: np.ndarray
    targets: np.ndarray
    impulse: np.ndarray | None = None
    released: np.ndarray | None = None

    @property
    def count(self) -> int:
        return int(self.particles.size)

    def projector(self, n: int) -> np.ndarray:
        """``P`` as ``(n, 3, 3)`` blocks (zero off the contacts)."""
        P = np.zeros((n, 3, 3))
        P[self.particles] = np.einsum("ka,kb->kab", self.normals, self.normals)
        return P

    def normal_part(self, y: np.ndarray) -> np.ndarray:
        """``P y`` for ``y`` of shape ``(n, 3)`` (flat accepted)."""
        y = np.asarray(y).reshape(-1, 3)
        out = np.zeros_like(y)
        nk = self.normals
        out[self.particles] = nk * np.einsum("ka,ka->k", nk, y[self.particles])[:, None]
        return out

    def tangential_part(self, y: np.ndarray) -> np.ndarray:
        """``S y = y - P y``."""
        y = np.asarray(y).reshape(-1, 3)
        return y - self.normal_part(y)

    def prescribed(self, v: np.ndarray) -> np.ndarray:
        """``z = n (c - n . v)``: the change of velocity along the normals the step makes,
        ``(n, 3)`` (zero off the contacts)."""
        out = np.zeros_like(v)
        nk = self.normals
        out[self.particles] = nk * (self.targets - np.einsum("ka,ka->k", nk,
                                                             v[self.particles]))[:, None]
        return out

    def with_impulse(self, impulse: np.ndarray) -> "Contacts":
        """The same contacts with the step's constraint impulse along each normal."""
        return Contacts(self.particles, self.body, self.normals, self.targets, impulse,
                        self.released)


NO_CONTACTS = Contacts(np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros((0, 3)),
                       np.zeros(0))


class BodyConstraint(Interaction):
    """The constraint contact of every particle with one :class:`~.colliders.Body`: no
    force; it prescribes the normal velocity of the particles touching the body.

    ``layer`` (m) is the distance from the body's surface at which particles are held: the
    body's contact thickness by default (the module docstring's ``thickness``), 0 to hold
    them on the surface itself (a guard under penalty springs, see :mod:`.cloth`)."""

    name = "body constraint"
    role = "contact"

    def __init__(self, body: Body, n: int, jit: bool | None = None, layer: float | None = None):
        if not isinstance(body, Body):
            raise ValueError(f"colliders must be Plane, Sphere or Capsule bodies, got {body!r}")
        self.body, self.n = body, n
        self.layer = float(body.contact.thickness if layer is None else layer)
        self.tolerance = TOLERANCE * float(body.contact.thickness)
        self.overshoot = OVERSHOOT * float(body.contact.thickness)
        self.kernels = constraint_kernels(type(body))
        self.mapped = {k: MappedKernel(f, jit=jit) for k, f in self.kernels.items()}

    @property
    def thickness(self) -> float:
        """The layer the contact holds (the kernels' ``h``)."""
        return self.layer

    def contact_parameters(self, t: float, dt: float) -> np.ndarray:
        """The body's geometry at t and at t + dt, as the symbolic step takes it."""
        return np.concatenate([self.body.parameters(t), self.body.parameters(t + dt)])

    def _columns(self, t, dt, count):
        """The kernels' inputs after ``x, v``: the body at t and t + dt, the layer, dt."""
        geometry = [np.broadcast_to(g, (count, np.size(g)))
                    for g in (*self.body.geometry(t), *self.body.geometry(t + dt))]
        return geometry + [np.full((count, 1), self.thickness), np.full((count, 1), dt)]

    def candidates(self, x, v, t, dt):
        """``(phi_0 (n,), normals (n, 3), targets (n,))`` of every particle for the step
        from t."""
        phi, normal, target = self.mapped["constraint"](x, v, *self._columns(t, dt, self.n))
        return phi.ravel(), normal, target.ravel()

    def vjp(self, x, v, t, dt, particles, lam, q, nu):
        """The gradients in x and v of ``-lam . n (n . q) + nu . z`` of ``particles``
        (``lam, q, nu``: ``(k, 3)``), each ``(k, 3)``."""
        k = particles.size
        return self.mapped["vjp"](x[particles], v[particles], *self._columns(t, dt, k),
                                  lam, q, nu)

    def jvp(self, x, v, t, dt, particles, q, nbar, dx, dv):
        """The derivative of ``-n (n . q) + nbar (nbar . z)`` of ``particles`` along
        ``(dx, dv)``, ``(k, 3)``."""
        k = particles.size
        return self.mapped["jvp"](x[particles], v[particles], *self._columns(t, dt, k), q,
                                  nbar, dx[particles], dv[particles])[0]

    def symbolic_constraint(self, X, V, S, dt):
        """``(phi_0, normals, targets)`` of every particle as CasADi expressions (``1 x n``,
        ``3 x n``, ``1 x n``) from the ``3 x n`` X, V and the body's parameters S
        (:meth:`contact_parameters`)."""
        n = X.shape[1]
        parts, at = [], 0
        for size in (*self.body.GEOMETRY.values(), *self.body.GEOMETRY.values()):
            parts.append(ca.repmat(S[at:at + size], 1, n))
            at += size
        phi, normal, target = self.kernels["constraint"].map(n)(
            X, V, *parts, ca.repmat(ca.DM(self.thickness), 1, n), ca.repmat(dt, 1, n))
        return phi, normal, target

    # no force: the family acts through the step's constraints only
    def forces(self, x, v, t, found):
        return None

    def blocks(self, x, v, t, kinds, found):
        return FamilyBlocks()

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        return None

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        return None

    def symbolic_forces(self, X, V, S):
        return ca.SX.zeros(3, X.shape[1])

    def symbolic_blocks(self, X, V, S, decisions=None):
        return FamilyBlocks()


def choose_contacts(families, x, v, t, dt, free_particles, previous: Contacts | None):
    """The :class:`Contacts` of a step from (x, v) at time t: for each particle that is not
    prescribed, the body of ``families`` (:class:`BodyConstraint`) it would reach deepest,
    if it touches one and is not released (module docstring)."""
    if not families:
        return NO_CONTACTS
    n = x.shape[0]
    best = np.full(n, np.inf)  # dt (n . v - c): how far past the layer it would end the step
    body, normals, targets = np.full(n, -1), np.zeros((n, 3)), np.zeros(n)
    tolerance = np.zeros(n)
    for b, family in enumerate(families):
        phi, normal, target = family.candidates(x, v, t, dt)
        reach = dt * (np.einsum("ka,ka->k", normal, v) - target)
        closer = reach < best
        best[closer], body[closer] = reach[closer], b
        normals[closer], targets[closer] = normal[closer], target[closer]
        tolerance[closer] = family.tolerance
    touching = (best <= tolerance) & free_particles
    released = np.zeros(n, bool)
    if previous is not None and previous.impulse is not None:
        pulled = np.zeros(n, bool)
        pulled[previous.particles[previous.impulse < 0]] = True
        leaving = ((previous.released if previous.released is not None else False)
                   & (np.einsum("ka,ka->k", normals, v) > targets))
        released = touching & (pulled | leaving)
    held = np.flatnonzero(touching & ~released)
    return Contacts(held, body[held], normals[held], targets[held], released=released)


def review_contacts(families, held: Contacts | None, x, v, t, dt, x1, free_particles):
    """``(revised, touching)`` after a step from (x, v) at t that ended at x1: ``held`` with
    the particles that ended inside a body's held layer (deeper than its overshoot,
    :data:`OVERSHOOT`) though the step did not hold them, each with the contact of the body it ended deepest in, as
    at the step's start (None if there are none: the step stands), and whether any particle
    ended in a body's contact layer."""
    n = x.shape[0]
    held = NO_CONTACTS if held is None else held
    unheld = free_particles.copy()
    unheld[held.particles] = False
    worst, body = np.zeros(n), np.full(n, -1)
    touching = False
    for b, family in enumerate(families):
        phi = signed_distances(family.body, x1, t + dt)
        touching = touching or bool(phi.min() < family.body.contact.thickness)
        depth = family.layer - family.overshoot - phi
        deeper = unheld & (depth > worst)
        worst[deeper], body[deeper] = depth[deeper], b
    late = np.flatnonzero(body >= 0)
    if not late.size:
        return None, touching
    normals, targets = np.zeros((late.size, 3)), np.zeros(late.size)
    for b, family in enumerate(families):
        mine = body[late] == b
        if mine.any():
            _, normal, target = family.candidates(x, v, t, dt)
            normals[mine], targets[mine] = normal[late[mine]], target[late[mine]]
    particles = np.concatenate([held.particles, late])
    order = np.argsort(particles)
    released = np.zeros(n, bool) if held.released is None else held.released.copy()
    released[late] = False
    return Contacts(particles[order], np.concatenate([held.body, body[late]])[order],
                    np.concatenate([held.normals, normals])[order],
                    np.concatenate([held.targets, targets])[order],
                    released=released), True


class HeldContacts(ContactConstraints):
    """The :class:`~.base.ContactConstraints` capability of a model whose ``families``
    include :class:`BodyConstraint` s (a cloth): the contacts its steps hold, and their
    derivatives, gathered over those families."""

    @property
    def constraint_families(self) -> tuple:
        """The families whose contacts the step holds (:class:`BodyConstraint`)."""
        return tuple(f for f in self.families if isinstance(f, BodyConstraint))

    def contacts(self, x, v, t: float, dt: float, previous=None):
        """The contacts a step from (x, v) at t holds (pinned and attached particles are
        never held: their motion is prescribed already)."""
        whole = self.free_mask().reshape(self.n, 3).all(axis=1)
        return choose_contacts(self.constraint_families, x, v, t, dt, whole, previous)

    def review_contacts(self, held, x, v, t: float, dt: float, x1):
        """``(revised, touching)``: ``held`` with the particles a step from (x, v) ended
        inside a body's layer without holding them (None if it held every one it had to),
        and whether the cloth ended in a body's contact layer."""
        whole = self.free_mask().reshape(self.n, 3).all(axis=1)
        return review_contacts(self.constraint_families, held, x, v, t, dt, x1, whole)

    def _by_body(self, contacts):
        for b, family in enumerate(self.constraint_families):
            pick = np.flatnonzero(contacts.body == b)
            if pick.size:
                yield family, pick, contacts.particles[pick]

    def contact_vjp(self, x, v, t: float, dt: float, contacts, lam, q, nu):
        gx, gv = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for family, pick, particles in self._by_body(contacts):
            bx, bv = family.vjp(x, v, t, dt, particles, lam[particles], q[pick], nu[particles])
            gx[particles], gv[particles] = bx, bv
        return gx, gv

    def contact_jvp(self, x, v, t: float, dt: float, contacts, q, dx, dv):
        out = np.zeros((self.n, 3))
        for family, pick, particles in self._by_body(contacts):
            out[particles] = family.jvp(x, v, t, dt, particles, q[pick],
                                        contacts.normals[pick], dx, dv)
        return out

    def contact_masks(self, contacts) -> np.ndarray:
        masks = np.zeros((len(self.constraint_families), self.n))
        masks[contacts.body, contacts.particles] = 1.0
        return masks.ravel()

    def contact_parameters(self, t: float, dt: float) -> np.ndarray:
        """The held bodies' geometry at t and t + dt, one body after another."""
        return np.concatenate([f.contact_parameters(t, dt) for f in self.constraint_families]
                              or [np.zeros(0)])

    def symbolic_contacts(self, X, V, G, dt, masks):
        normals, targets = ca.SX.zeros(3, self.n), ca.SX.zeros(1, self.n)
        at = 0
        for b, family in enumerate(self.constraint_families):
            size = family.contact_parameters(0.0, 1.0).size
            _, normal, target = family.symbolic_constraint(X, V, G[at:at + size], dt)
            at += size
            held = ca.reshape(masks[b * self.n:(b + 1) * self.n], 1, self.n)
            normals += ca.repmat(held, 3, 1) * normal
            targets += held * target
        return normals, targets
