r"""The step's hold: a particle that would reach a body within a step has its velocity along
the body's normal prescribed in the implicit step's solve (the filter of Baraff and Witkin's
modified CG), instead of meeting a stiff spring only once it is inside.

For the step from t, ``phi_0``, ``phi_1`` are a particle's signed distances to the body at t
and at t + dt and ``n`` the latter's outward normal.  A held particle ends the step with

    n . v+ = c = (phi_0 - phi_1) / dt + beta (layer - phi_0) / dt,   beta = 1 if phi_0 >= layer

(else :data:`CORRECTION`): an arriving particle ends on the layer's surface, one inside it
is moved back a fraction per step.  A particle is held when it would end the step within
the layer moving as it does, ``dt (n . v - c) <= tolerance``, on the body it would reach
deepest; its tangential velocity stays free (no friction yet).  One the hold pulled
(negative impulse) is released at the next step, and stays released while it moves away.
The step solves ``S (A dv - b) = 0``, ``P (dv - z) = 0`` with ``P = n n^T`` per held
particle, ``S = I - P``, ``z = n (c - n . v)`` (:mod:`~..integrators.held_solve`); its exact
derivative adds those of the normals and targets, which :class:`HeldBody`'s kernels give.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..kernels import MappedKernel
from .colliders import Body
from .interaction import FamilyBlocks, Interaction, StepSpan

TOLERANCE = 0.25  # of the thickness: a particle this close to the layer's surface touches it
OVERSHOOT = 0.1  # of the thickness: a step that leaves a particle this far past it is redone
CORRECTION = 0.5  # of a particle's depth in the layer undone per step (beta)


@functools.lru_cache(maxsize=None)
def hold_kernels(body_type: type) -> dict[str, ca.Function]:
    """Per particle ``(x, v, *geometry at t, *geometry at t + dt, layer, dt)``:
    ``hold -> (phi_0, n, c)``, ``vjp(..., lam, q, nu) -> (gx, gv)``, the gradients of
    ``-lam . n (n . q) + nu . z``, and ``jvp(..., q, nbar, dx, dv) -> d``, the derivative of
    ``-n (n . q) + nbar (nbar . z)`` with ``nbar`` held (module docstring)."""
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
    name = f"{body_type.kind}_hold"
    return {
        "hold": ca.Function(name, args, [phi, n, c]),
        "vjp": ca.Function(f"{name}_vjp", args + [lam, q, nu],
                           [ca.gradient(scalar, x), ca.gradient(scalar, v)]),
        "jvp": ca.Function(f"{name}_jvp", args + [q, nbar, dx, dv],
                           [ca.jtimes(vector, ca.vertcat(x, v), ca.vertcat(dx, dv))]),
    }


@dataclass(frozen=True)
class HeldSet:
    """The particles a step holds: ``particles`` ``(k,)`` (sorted), the ``body`` each is held
    on (index into the hold's bodies), their unit ``normals`` ``(k, 3)`` and target normal
    velocities ``targets`` ``(k,)`` at the step's start; after the solve, ``impulse``
    ``(k,)`` along each normal (negative: the hold pulled); ``released`` ``(n,)``, the
    particles let go.  ``P`` is the projector on the held directions (``n n^T`` each)."""

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
        """``P`` as ``(n, 3, 3)`` blocks (zero off the held particles)."""
        P = np.zeros((n, 3, 3))
        P[self.particles] = np.einsum("ka,kb->kab", self.normals, self.normals)
        return P

    def held_part(self, y: np.ndarray) -> np.ndarray:
        """``P y`` for ``y`` of shape ``(n, 3)`` (flat accepted)."""
        y = np.asarray(y).reshape(-1, 3)
        out = np.zeros_like(y)
        nk = self.normals
        out[self.particles] = nk * np.einsum("ka,ka->k", nk, y[self.particles])[:, None]
        return out

    def unheld_part(self, y: np.ndarray) -> np.ndarray:
        """``S y = y - P y``."""
        y = np.asarray(y).reshape(-1, 3)
        return y - self.held_part(y)

    def prescribed(self, v: np.ndarray) -> np.ndarray:
        """``z = n (c - n . v)``: the change of velocity the step makes along the held
        directions, ``(n, 3)`` (zero off the held particles)."""
        out = np.zeros_like(v)
        nk = self.normals
        out[self.particles] = nk * (self.targets - np.einsum("ka,ka->k", nk,
                                                             v[self.particles]))[:, None]
        return out

    def solved(self, residual: np.ndarray) -> "HeldSet":
        """The same set with the impulses of a solved step, from ``A dv - b`` (flat)."""
        r = residual.reshape(-1, 3)[self.particles]
        return HeldSet(self.particles, self.body, self.normals, self.targets,
                       np.einsum("ka,ka->k", self.normals, r), self.released)


NOTHING_HELD = HeldSet(np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros((0, 3)),
                       np.zeros(0))


class HeldBody:
    """One body the hold holds particles on, ``layer`` (m) from its surface, with its
    kernels (:func:`hold_kernels`) mapped over particles."""

    def __init__(self, body: Body, layer: float, jit: bool | None):
        if not isinstance(body, Body):
            raise ValueError(f"colliders must be Plane, Sphere or Capsule bodies, got {body!r}")
        self.body, self.layer = body, float(layer)
        self.tolerance = TOLERANCE * float(body.contact.thickness)
        self.overshoot = OVERSHOOT * float(body.contact.thickness)
        self.kernels = hold_kernels(type(body))
        self.mapped = {k: MappedKernel(f, jit=jit) for k, f in self.kernels.items()}

    def parameters(self, t: float, dt: float) -> np.ndarray:
        """The body's geometry at t and at t + dt, as the symbolic step takes it."""
        return np.concatenate([self.body.parameters(t), self.body.parameters(t + dt)])

    def _columns(self, t, dt, count):
        geometry = [np.broadcast_to(g, (count, np.size(g)))
                    for g in (*self.body.geometry(t), *self.body.geometry(t + dt))]
        return geometry + [np.full((count, 1), self.layer), np.full((count, 1), dt)]

    def candidates(self, x, v, t, dt):
        """``(phi_0 (n,), normals (n, 3), targets (n,))`` of every particle, step from t."""
        phi, normal, target = self.mapped["hold"](x, v, *self._columns(t, dt, len(x)))
        return phi.ravel(), normal, target.ravel()

    def vjp(self, x, v, t, dt, particles, lam, q, nu):
        """The gradients in x and v of ``-lam . n (n . q) + nu . z`` over ``particles``."""
        return self.mapped["vjp"](x[particles], v[particles],
                                  *self._columns(t, dt, particles.size), lam, q, nu)

    def jvp(self, x, v, t, dt, particles, q, nbar, dx, dv):
        """The derivative of ``-n (n . q) + nbar (nbar . z)`` along ``(dx, dv)``."""
        return self.mapped["jvp"](x[particles], v[particles],
                                  *self._columns(t, dt, particles.size), q, nbar,
                                  dx[particles], dv[particles])[0]

    def symbolic(self, X, V, G, dt):
        """``(phi_0, normals, targets)`` of every particle in CasADi from the ``3 x n`` X, V
        and the geometry G of :meth:`parameters`."""
        n = X.shape[1]
        parts, at = [], 0
        for size in (*self.body.GEOMETRY.values(), *self.body.GEOMETRY.values()):
            parts.append(ca.repmat(G[at:at + size], 1, n))
            at += size
        return self.kernels["hold"].map(n)(X, V, *parts, ca.repmat(ca.DM(self.layer), 1, n),
                                           ca.repmat(dt, 1, n))


class BodyHold(Interaction):
    """The step's hold on ``bodies``: no force; its decision for a step is the
    :class:`HeldSet` (None: nothing held).  ``layer`` (m): how far from each body's
    surface particles are held, its contact thickness by default, 0 for the surface
    itself (under penalty springs: ``collision="guarded"``, :mod:`.collisions`)."""

    name = "body hold"
    role = "contact"
    holds = True

    def __init__(self, bodies, n: int, jit: bool | None = None, layer: float | None = None):
        self.n = n
        self.bodies = tuple(HeldBody(b, b.contact.thickness if layer is None else layer, jit)
                            for b in bodies)

    def decide(self, step: StepSpan, carried) -> HeldSet | None:
        """Each free particle that would reach a body's layer, on the body it would reach
        deepest, unless the last step's ``carried`` (:meth:`carry`) releases it."""
        x, v, n = step.x, step.v, step.x.shape[0]
        best = np.full(n, np.inf)  # dt (n . v - c): how far past the layer it would end
        body, normals, targets = np.full(n, -1), np.zeros((n, 3)), np.zeros(n)
        tolerance = np.zeros(n)
        for b, held in enumerate(self.bodies):
            phi, normal, target = held.candidates(x, v, step.t, step.dt)
            reach = step.dt * (np.einsum("ka,ka->k", normal, v) - target)
            closer = reach < best
            best[closer], body[closer] = reach[closer], b
            normals[closer], targets[closer] = normal[closer], target[closer]
            tolerance[closer] = held.tolerance
        touching = (best <= tolerance) & step.free
        released = np.zeros(n, bool)
        if carried is not None:
            pulled = np.zeros(n, bool)
            pulled[carried[0]] = True
            leaving = carried[1] & (np.einsum("ka,ka->k", normals, v) > targets)
            released = touching & (pulled | leaving)
        held = np.flatnonzero(touching & ~released)
        if not held.size:
            return None
        return HeldSet(held, body[held], normals[held], targets[held], released=released)

    def stops(self, found, end):
        """A particle held, or one that ended in a body's contact layer."""
        touching = [end.distances(b.body).min() < b.body.contact.thickness for b in self.bodies]
        return found is not None or any(touching)

    def revise(self, found, end, stopped):
        """``found`` plus the free particles the step ended deeper than a body's layer less
        its overshoot (:data:`OVERSHOOT`) without holding them, each held as at the step's
        start on the body it ended deepest in; None if there are none."""
        held, n = NOTHING_HELD if found is None else found, end.x.shape[0]
        unheld = end.free.copy()
        unheld[held.particles] = False
        worst, body = np.zeros(n), np.full(n, -1)
        for b, layer in enumerate(self.bodies):
            depth = layer.layer - layer.overshoot - end.distances(layer.body)
            deeper = unheld & (depth > worst)
            worst[deeper], body[deeper] = depth[deeper], b
        late = np.flatnonzero(body >= 0)
        if not late.size:
            return None
        normals, targets = np.zeros((late.size, 3)), np.zeros(late.size)
        for b, layer in enumerate(self.bodies):
            mine = body[late] == b
            if mine.any():
                _, normal, target = layer.candidates(end.x, end.v, end.t, end.dt)
                normals[mine], targets[mine] = normal[late[mine]], target[late[mine]]
        particles = np.concatenate([held.particles, late])
        order = np.argsort(particles)
        released = np.zeros(n, bool) if held.released is None else held.released.copy()
        released[late] = False
        return HeldSet(particles[order], np.concatenate([held.body, body[late]])[order],
                       np.concatenate([held.normals, normals])[order],
                       np.concatenate([held.targets, targets])[order], released=released)

    def solved(self, found, residual):
        return None if found is None else found.solved(residual)

    def carry(self, found):
        """The particles the hold pulled (released at the next step) and those it released."""
        return None if found is None else (found.particles[found.impulse < 0], found.released)

    def decision_parameters(self, found, t, dt):
        """Which particles are held on each body (0/1, body after body), then each body's
        geometry at t and t + dt."""
        masks = np.zeros((len(self.bodies), self.n))
        if found is not None:
            masks[found.body, found.particles] = 1.0
        return np.concatenate([masks.ravel(), *(b.parameters(t, dt) for b in self.bodies)])

    def _by_body(self, held):
        for b, layer in enumerate(self.bodies):
            pick = np.flatnonzero(held.body == b)
            if pick.size:
                yield layer, pick, held.particles[pick]

    def vjp(self, x, v, t, dt, held, lam, q, nu):
        """``(gx, gv)``: gradients of ``sum_k -lam_k . n_k (n_k . q_k) + nu_k . z_k``."""
        gx, gv = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for layer, pick, particles in self._by_body(held):
            gx[particles], gv[particles] = layer.vjp(x, v, t, dt, particles, lam[particles],
                                                     q[pick], nu[particles])
        return gx, gv

    def jvp(self, x, v, t, dt, held, q, dx, dv):
        """The derivative of ``-n_k (n_k . q_k) + nbar_k (nbar_k . z_k)`` along (dx, dv)."""
        out = np.zeros((self.n, 3))
        for layer, pick, particles in self._by_body(held):
            out[particles] = layer.jvp(x, v, t, dt, particles, q[pick], held.normals[pick],
                                       dx, dv)
        return out

    def symbolic_held(self, X, V, D, dt):
        """``(normals 3 x n, targets 1 x n)`` of the held particles (zero elsewhere), from
        :meth:`decision_parameters` D."""
        n, masks = self.n, D[:len(self.bodies) * self.n]
        normals, targets = ca.SX.zeros(3, n), ca.SX.zeros(1, n)
        at = masks.shape[0]
        for b, layer in enumerate(self.bodies):
            size = layer.parameters(0.0, 1.0).size
            _, normal, target = layer.symbolic(X, V, D[at:at + size], dt)
            at += size
            held = ca.reshape(masks[b * n:(b + 1) * n], 1, n)
            normals += ca.repmat(held, 3, 1) * normal
            targets += held * target
        return normals, targets

    # no force: the hold acts through the step's solve only
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
