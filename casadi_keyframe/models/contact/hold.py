r"""The step's hold: a particle that would reach a body within a step has its velocity along
the body's normal prescribed in the implicit step's solve (the filter of Baraff and Witkin's
modified CG), instead of meeting a stiff spring only once it is inside.

For the step from t, ``phi_0``, ``phi_1`` are a particle's signed distances to the body at t
and at t + dt and ``n`` the latter's outward normal.  A held particle ends the step with

    n . v+ = c = (phi_0 - phi_1) / dt + beta (layer - phi_0) / dt,   beta = 1 if phi_0 >= layer

(else :data:`CORRECTION`): an arriving particle ends on the layer's surface, one inside it
is moved back a fraction per step.  A particle is held when it would end the step within
the layer moving as it does, ``dt (n . v - c) <= tolerance``, on the body it would reach
deepest.  On a body with a tangential law (friction, ``Contact.friction``) the hold also holds
or pushes its tangential velocity (:mod:`.stick_slide`, :mod:`.tangential`,
:mod:`.held_set`); without, it stays free.  One the
hold pulled (negative impulse) is released and the step solved again (contact only pushes),
unless the pull would move it less than the tolerance over the step; one still pulled when
the step stops revising is released at the next.  A released particle stays released while
it moves away.  The step solves ``S (A dv - b) = 0``, ``P (dv - z) = 0``
(:mod:`~...integrators.held_solve`); its exact derivative adds those of the normals, targets
and body velocities, which the kernels of :func:`hold_kernels` give.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from ...kernels import MappedKernel
from .colliders import Body
from .held_set import NOTHING_HELD, HeldSet
from .stick_slide import StickSlide, tangential_law
from ..interaction import FamilyBlocks, Interaction, StepSpan

TOLERANCE = 0.25  # of the thickness: a particle this close to the layer's surface touches it
OVERSHOOT = 0.1  # of the thickness: a step that leaves a particle this far past it is redone
CORRECTION = 0.5  # of a particle's depth in the layer undone per step (beta)


@functools.lru_cache(maxsize=None)
def hold_kernels(body_type: type, friction: bool = False) -> dict[str, ca.Function]:
    """Per particle ``(x, v, *geometry at t, *geometry at t + dt, layer, dt)`` (with
    ``friction``, a tangential law, also the flags ``a`` (normal held) and ``s`` (stick)):
    ``hold -> (phi_0, n, c[, v_body])``; ``vjp(..., lam, q, nu) -> (gx, gv)``, the gradients of
    ``-(a - s) lam . n (n . q) + nu . z``; ``jvp(..., q, nbar, dx, dv) -> d``, the derivative
    of ``-(a - s) n (n . q) + s z + (a - s) nbar (nbar . z)`` with ``nbar`` held; without
    friction ``a = 1``, ``s = 0`` (module docstring, :mod:`.held_set` for z)."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    start = {key: ca.SX.sym(f"{key}_0", size) for key, size in body_type.GEOMETRY.items()}
    end = {key: ca.SX.sym(f"{key}_1", size) for key, size in body_type.GEOMETRY.items()}
    h, dt = ca.SX.sym("h"), ca.SX.sym("dt")
    phi, _, _ = body_type.surface(x, **start)
    phi_end, n, v_body = body_type.surface(x, **end)
    c = (phi - phi_end) / dt + ca.if_else(phi >= h, 1.0, CORRECTION) * (h - phi) / dt
    z = n * (c - ca.dot(n, v))
    args = [x, v, *start.values(), *end.values(), h, dt]
    outputs = [phi, n, c]
    lam, q, nu, nbar = (ca.SX.sym(s, 3) for s in ("lam", "q", "nu", "nbar"))
    dx, dv = ca.SX.sym("dx", 3), ca.SX.sym("dv", 3)
    if friction:
        a, s = ca.SX.sym("a"), ca.SX.sym("s")
        slip = v_body - v
        z = a * z + s * (slip - n * ca.dot(n, slip))
        args, outputs = args + [a, s], outputs + [v_body]
        scalar = -(a - s) * ca.dot(lam, n) * ca.dot(n, q) + ca.dot(nu, z)
        vector = -(a - s) * n * ca.dot(n, q) + s * z + (a - s) * nbar * ca.dot(nbar, z)
    else:
        scalar = -ca.dot(lam, n) * ca.dot(n, q) + ca.dot(nu, z)
        vector = -n * ca.dot(n, q) + nbar * ca.dot(nbar, z)
    name = f"{body_type.kind}_{'friction_' if friction else ''}hold"
    return {
        "hold": ca.Function(name, args, outputs),
        "vjp": ca.Function(f"{name}_vjp", args + [lam, q, nu],
                           [ca.gradient(scalar, x), ca.gradient(scalar, v)]),
        "jvp": ca.Function(f"{name}_jvp", args + [q, nbar, dx, dv],
                           [ca.jtimes(vector, ca.vertcat(x, v), ca.vertcat(dx, dv))]),
    }


class HeldBody:
    """One body the hold holds particles on, ``layer`` (m) from its surface, with its
    kernels (:func:`hold_kernels`) mapped over particles and its tangential ``law``
    (:func:`~.stick_slide.tangential_law`, None: none); ``penalty``: whether the penalty
    springs also act on it (their push is part of the normal force friction is bounded by)."""

    def __init__(self, body: Body, layer: float, jit: bool | None, penalty: bool = False):
        if not isinstance(body, Body):
            raise ValueError(f"colliders must be bodies (Plane, Sphere, Capsule, MeshBody), got "
                             f"{body!r}")
        self.body, self.layer, self.penalty = body, float(layer), penalty
        self.tolerance = TOLERANCE * float(body.contact.thickness)
        self.overshoot = OVERSHOOT * float(body.contact.thickness)
        self.law = tangential_law(body.contact)
        self.sizes = tuple(body.GEOMETRY.values()) * 2
        self.kernels = hold_kernels(type(body), self.law is not None)
        self.mapped = {k: MappedKernel(f, jit=jit) for k, f in self.kernels.items()}

    def parameters(self, t: float, dt: float) -> np.ndarray:
        """The body's geometry at t and at t + dt, as the symbolic step takes it."""
        return np.concatenate([self.body.parameters(t), self.body.parameters(t + dt)])

    def rows(self, x, t, dt, reach=None) -> np.ndarray:
        """Each point's geometry at t and t + dt as one row ``(n, g)`` (exact within
        ``reach``, :meth:`~.colliders.Body.local_geometry`)."""
        return np.hstack([*self.body.local_geometry(x, t, reach),
                          *self.body.local_geometry(x, t + dt, reach)])

    def columns(self, rows, dt, flags=None):
        """The kernels' columns after x and v for the particles of geometry ``rows``: the
        geometry, layer and dt, and with a law the flags (default: normal held, sticking)."""
        at = np.cumsum((0,) + self.sizes)
        count = len(rows)
        columns = [rows[:, a:b] for a, b in zip(at[:-1], at[1:])]
        columns += [np.full((count, 1), self.layer), np.full((count, 1), dt)]
        if self.law is not None:
            columns += [np.ones((count, 1)), np.zeros((count, 1))] if flags is None else flags
        return columns

    def candidates(self, x, v, t, dt):
        """``(phi_0 (n,), normals (n, 3), targets (n,), velocities (n, 3) or None, rows)`` of
        every particle, step from t."""
        rows = self.rows(x, t, dt, self.body.reach(v, t, dt))
        out = self.mapped["hold"](x, v, *self.columns(rows, dt))
        velocity = out[3] if self.law is not None else None
        return out[0].ravel(), out[1], out[2].ravel(), velocity, rows

    def _flags(self, held, pick):
        if self.law is None:
            return None
        return [held.normal[pick, None].astype(float), held.stick[pick, None].astype(float)]

    def vjp(self, x, v, dt, held, pick, lam, q, nu):
        """The gradients in x and v of ``-(a - s) lam . n (n . q) + nu . z`` over the held
        particles ``pick`` (indices into ``held``) on this body."""
        particles = held.particles[pick]
        return self.mapped["vjp"](x[particles], v[particles],
                                  *self.columns(held.geometry[pick], dt, self._flags(held, pick)),
                                  lam, q, nu)

    def jvp(self, x, v, dt, held, pick, q, dx, dv):
        """The derivative of the hold's terms (:func:`hold_kernels`) along ``(dx, dv)``."""
        particles = held.particles[pick]
        return self.mapped["jvp"](x[particles], v[particles],
                                  *self.columns(held.geometry[pick], dt, self._flags(held, pick)),
                                  q, held.normals[pick], dx[particles], dv[particles])[0]

    def symbolic_columns(self, G, n: int) -> list:
        """The kernels' geometry columns for n particles from G: :meth:`parameters` (one
        column for all) or ``g x n`` (one per particle)."""
        parts, at = [], 0
        for size in self.sizes:
            block = G[at:at + size, :]
            parts.append(block if block.shape[1] == n else ca.repmat(block, 1, n))
            at += size
        return parts

    def symbolic(self, X, V, parts, dt, flags=None):
        """The hold kernel's outputs for every particle in CasADi from the ``3 x n`` X, V and
        the geometry columns ``parts`` (:meth:`symbolic_columns`)."""
        n = X.shape[1]
        extra = [] if self.law is None else flags
        return self.kernels["hold"].map(n)(X, V, *parts, ca.repmat(ca.DM(self.layer), 1, n),
                                           ca.repmat(dt, 1, n), *extra)


class BodyHold(Interaction):
    """The step's hold on ``bodies``: no force; its decision for a step is the
    :class:`~.held_set.HeldSet` (None: nothing held).  ``layer`` (m): how far from each
    body's surface particles are held, its contact thickness by default, 0 for the surface
    itself (under penalty springs: ``collision="guarded"``, :mod:`.collisions`); ``layers``
    gives one per body instead; ``penalty``: which bodies the penalty springs act on too;
    ``masses`` (kg): the particles', which say how hard a pull is (:meth:`revise`) and
    friction's normal impulse.  On bodies with a tangential law its stick and slide
    decisions are ``stick_slide``'s (:class:`~.stick_slide.StickSlide`, None: no such body)."""

    name = "body hold"
    role = "contact"
    holds = True

    def __init__(self, bodies, n: int, jit: bool | None = None, layer: float | None = None,
                 layers=None, penalty=None, masses=None, gravity=(0.0, 0.0, -9.81)):
        self.n = n
        bodies = tuple(bodies)
        if layers is None:
            layers = [b.contact.thickness if layer is None else layer for b in bodies]
        penalty = [False] * len(bodies) if penalty is None else penalty
        self.bodies = tuple(HeldBody(b, h, jit, p) for b, h, p in zip(bodies, layers, penalty))
        if masses is None:
            raise ValueError("a hold needs the particles' masses (the pulls it lets go, "
                             "friction's normal impulse): pass masses=")
        self.masses = np.asarray(masses, float)
        self.stick_slide = None
        if any(b.law is not None for b in self.bodies):
            self.stick_slide = StickSlide(self.bodies, masses, gravity, CORRECTION, jit)

    def decide(self, step: StepSpan, carried) -> HeldSet | None:
        """Each free particle that would reach a body's layer, on the body it would reach
        deepest, unless the last step's ``carried`` (:meth:`carry`) releases it; on bodies
        with a tangential law also those in the contact layer, sticking or sliding
        (:mod:`.stick_slide`)."""
        x, v, n = step.x, step.v, step.x.shape[0]
        best = np.full(n, np.inf)  # dt (n . v - c): how far past the layer it would end
        body, normals, targets = np.full(n, -1), np.zeros((n, 3)), np.zeros(n)
        tolerance, seen = np.zeros(n), []
        for b, held in enumerate(self.bodies):
            phi, normal, target, velocity, rows = held.candidates(x, v, step.t, step.dt)
            seen.append((phi, normal, target, velocity, rows))
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
        held = touching & ~released
        if self.stick_slide is not None:
            return self.stick_slide.decide(step, held, body, seen, released)
        held = np.flatnonzero(held)
        if not held.size:
            return None
        return HeldSet(held, body[held], normals[held], targets[held], released=released,
                       geometry=self._rows(seen, body, held))

    @staticmethod
    def _rows(seen, body, particles):
        """The geometry rows of ``particles``, each from the body it is held on."""
        width = max(s[4].shape[1] for s in seen)  # bodies of different kinds: zero-padded
        rows = np.zeros((particles.size, width))
        for b, s in enumerate(seen):
            mine = body[particles] == b
            rows[mine, :s[4].shape[1]] = s[4][particles[mine]]
        return rows

    def stops(self, found, end):
        """A particle held, or one that ended in a body's contact layer."""
        touching = [end.distances(b.body).min() < b.body.contact.thickness for b in self.bodies]
        return (found is not None and found.count > 0) or any(touching)

    def revise(self, found, end, stopped):
        """``found`` less the particles its solve pulled onto a body (:meth:`_pulled_off`;
        contact only pushes, so they are released and the step solved again), plus the free
        particles the step ended deeper than a body's layer less its overshoot
        (:data:`OVERSHOOT`) without holding them, each held as at the step's start on the
        body it ended deepest in; with a tangential law, the stick and slide decisions the
        step's end refutes (:mod:`.stick_slide`); None if nothing changes."""
        held, n = NOTHING_HELD if found is None else found, end.x.shape[0]
        pulled = self._pulled_off(held, end.dt)
        if pulled.any():
            found = held = held.without(pulled, n)
        unheld = end.free.copy()
        unheld[held.particles[held.normal] if held.frictional else held.particles] = False
        worst, body = np.zeros(n), np.full(n, -1)
        for b, layer in enumerate(self.bodies):
            depth = layer.layer - layer.overshoot - end.distances(layer.body)
            deeper = unheld & (depth > worst)
            worst[deeper], body[deeper] = depth[deeper], b
        late = np.flatnonzero(body >= 0)
        if self.stick_slide is not None:
            revised = self.stick_slide.revise(found, end, late, body)
            return found if revised is None and pulled.any() else revised
        if not late.size:
            return found if pulled.any() else None
        normals, targets = np.zeros((late.size, 3)), np.zeros(late.size)
        rows = np.zeros((late.size, max(sum(b.sizes) for b in self.bodies)))
        for b, layer in enumerate(self.bodies):
            mine = body[late] == b
            if mine.any():
                _, normal, target, _, row = layer.candidates(end.x, end.v, end.t, end.dt)
                normals[mine], targets[mine] = normal[late[mine]], target[late[mine]]
                rows[mine, :row.shape[1]] = row[late[mine]]
        particles = np.concatenate([held.particles, late])
        order = np.argsort(particles)
        released = np.zeros(n, bool) if held.released is None else held.released.copy()
        released[late] = False
        geometry = rows if not held.count else np.vstack([held.geometry, rows])
        return HeldSet(particles[order], np.concatenate([held.body, body[late]])[order],
                       np.concatenate([held.normals, normals])[order],
                       np.concatenate([held.targets, targets])[order], released=released,
                       geometry=geometry[order])

    def _pulled_off(self, held, dt):
        """``(k,)``: the members the solved step pulls onto their body, each harder than a
        pull that moves it less than its body's tolerance over the step (``m tolerance /
        dt``: within it, it touches)."""
        if held.impulse is None:
            return np.zeros(held.count, bool)
        tolerance = np.array([b.tolerance for b in self.bodies])
        return held.pulled(self.masses[held.particles] * tolerance[held.body] / dt)

    def solved(self, found, residual):
        return None if found is None else found.solved(residual)

    def carry(self, found):
        """The particles the hold pulled (released at the next step) and those it released."""
        if found is None:
            return None
        return found.particles[found.pulled()], found.released

    def decision_parameters(self, found, t, dt):
        """Which particles are held on each body (0/1, body after body), then each body's
        geometry at t and t + dt (a mesh's: one column per particle), then with a tangential law
        the flags of :meth:`.stick_slide.StickSlide.parameters`."""
        masks = np.zeros((len(self.bodies), self.n))
        if found is not None:
            masks[found.body, found.particles] = 1.0
        geometry = []
        for b, layer in enumerate(self.bodies):
            if layer.body.local:
                rows = np.zeros((self.n, sum(layer.sizes)))
                if found is not None:
                    pick = found.body == b
                    rows[found.particles[pick]] = found.geometry[pick, :rows.shape[1]]
                geometry.append(rows.ravel())  # ca.reshape(., g, n) is column-major
            else:
                geometry.append(layer.parameters(t, dt))
        extra = [] if self.stick_slide is None else [self.stick_slide.parameters(found)]
        return np.concatenate([masks.ravel(), *geometry, *extra])

    def _by_body(self, held):
        for b, layer in enumerate(self.bodies):
            pick = np.flatnonzero(held.body == b)
            if pick.size:
                yield layer, pick, held.particles[pick]

    def vjp(self, x, v, t, dt, held, lam, q, nu):
        """``(gx, gv)``: gradients of ``sum_k -(a - s) lam_k . n_k (n_k . q_k) + nu_k . z_k``."""
        gx, gv = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for layer, pick, particles in self._by_body(held):
            gx[particles], gv[particles] = layer.vjp(x, v, dt, held, pick, lam[particles],
                                                     q[pick], nu[particles])
        if self.stick_slide is not None:  # the sliding impulses join b: S lam multiplies them
            fx, fv = self.stick_slide.vjp(x, v, dt, held, held.unheld_part(lam),
                                          held.change(q, v))
            gx, gv = gx + fx, gv + fv
        return gx, gv

    def jvp(self, x, v, t, dt, held, q, dx, dv):
        """The derivative of the hold's terms (:func:`hold_kernels`) along (dx, dv)."""
        out = np.zeros((self.n, 3))
        for layer, pick, particles in self._by_body(held):
            out[particles] = layer.jvp(x, v, dt, held, pick, q[pick], dx, dv)
        if self.stick_slide is not None:
            out += held.unheld_part(self.stick_slide.jvp(x, v, dt, held, held.change(q, v),
                                                         dx, dv))
        return out

    def symbolic_held(self, X, V, D, dt):
        """``(normals 3 x n, targets 1 x n)`` of the held particles (zero elsewhere), from
        :meth:`decision_parameters` D; with a tangential law also ``(velocities 3 x n, normal 1 x n,
        stick 1 x n, sliding impulses 3 x n, their matrices 9 x n)``."""
        n, masks = self.n, D[:len(self.bodies) * self.n]
        at = masks.shape[0]
        tangential = self.stick_slide
        flags = None if tangential is None else tangential.symbolic(D, self.decision_size())
        normals, targets, velocity = ca.SX.zeros(3, n), ca.SX.zeros(1, n), ca.SX.zeros(3, n)
        pushed, matrices = ca.SX.zeros(3, n), ca.SX.zeros(9, n)
        for b, layer in enumerate(self.bodies):
            if layer.body.local:
                size = sum(layer.sizes) * n
                G = ca.reshape(D[at:at + size], sum(layer.sizes), n)
            else:
                size = layer.parameters(0.0, 1.0).size
                G = D[at:at + size]
            at += size
            parts = layer.symbolic_columns(G, n)
            out = layer.symbolic(X, V, parts, dt, None if flags is None else list(flags[:2]))
            held = ca.reshape(masks[b * n:(b + 1) * n], 1, n)
            normals += ca.repmat(held, 3, 1) * out[1]
            targets += held * out[2]
            if flags is not None:
                velocity += ca.repmat(held, 3, 1) * out[3]
                if layer.law is not None:
                    columns = parts + [ca.repmat(ca.DM(layer.layer), 1, n), ca.repmat(dt, 1, n)]
                    F, B = tangential.symbolic_impulses(b, X, V, columns, dt, flags)
                    pushed += ca.repmat(held, 3, 1) * F
                    matrices += ca.repmat(held, 9, 1) * B
        if flags is None:
            return normals, targets
        return normals, targets, velocity, flags[0], flags[1], pushed, matrices

    # no force: the hold acts through the step's solve only
    def forces(self, x, v, t, found):
        return None

    def blocks(self, x, v, t, kinds, found):
        return FamilyBlocks()

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        return None

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        return None

    def symbolic_forces(self, X, V, S, decisions=None):
        return ca.SX.zeros(3, X.shape[1])

    def symbolic_blocks(self, X, V, S, decisions=None):
        return FamilyBlocks()

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        return type(X).zeros(3, X.shape[1])  # the hold acts through the step's filter

    def step_jacobian(self, x, v, w, q, times, dt):
        return None
