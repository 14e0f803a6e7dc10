r"""Coulomb friction through the step's hold: stick holds, slide pushes.

A particle in contact with a body of friction ``mu`` (held on it, or inside the penalty
springs' layer) either **sticks**: the hold prescribes its tangential velocity, the body's
surface velocity there (rotation included), through the same filter that holds its normal;
or **slides**: it gets the impulse

    F = -mu N t,   N = m max(a (c - n . v) + (1 - a) n . (v_body - v), 0) + dt m max(-n . g, 0),
    t = unit(T (v - v_body) + SLIP d)

where ``N`` is the normal impulse that stops the particle's approach over the step
(``a = 1``: held, to the hold's target ``c``) and carries its weight, ``T = I - n n^T``, and
``d`` (a step's decision) the direction it starts sliding in where its slip is nil.  F is a
function of the step's start state, so the solve stays symmetric and the law's derivative
is exact (:func:`friction_kernels`).  A contact starts a step sliding if it slips (faster
than :data:`SLIP` against the body's surface), else sticking.  After a solve a sticking particle
whose tangential impulse ``r_t`` leaves the cone (``|r_t| > mu N``) slides (``d = -r_t /
|r_t|``), and a sliding one whose slip turned against ``t`` by the step's end sticks; the
step is solved again.  The gradient is that of the modes the step chose: exact within them
(as DiffCloth's), one-sided at a stick/slide switch, where the simulated map is continuous
only up to the difference between ``r_t``'s direction and ``t``.
"""
from __future__ import annotations

import functools
from dataclasses import replace

import casadi as ca
import numpy as np

from ...kernels import MappedKernel
from .held_set import HeldSet

SLIP = 1e-4  # m/s: the slip below which a slide leans on its decided direction d


def _tangent(normals, a):
    return a - normals * np.einsum("ka,ka->k", normals, a)[:, None]


@functools.lru_cache(maxsize=None)
def friction_kernels(body_type: type, correction: float) -> dict[str, ca.Function]:
    """Per particle ``(x, v, *geometry at t, *geometry at t + dt, layer, dt, a, m, g, d,
    mu)``: ``impulse -> (F, N)`` (module docstring), ``vjp(..., lam) -> (gx, gv)`` the
    gradients of ``lam . F``, ``jvp(..., dx, dv) -> dF``."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    start = {key: ca.SX.sym(f"{key}_0", size) for key, size in body_type.GEOMETRY.items()}
    end = {key: ca.SX.sym(f"{key}_1", size) for key, size in body_type.GEOMETRY.items()}
    h, dt, a, m, mu = (ca.SX.sym(s) for s in ("h", "dt", "a", "m", "mu"))
    g, d = ca.SX.sym("g", 3), ca.SX.sym("d", 3)
    phi, _, _ = body_type.surface(x, **start)
    phi_end, n, v_body = body_type.surface(x, **end)
    c = (phi - phi_end) / dt + ca.if_else(phi >= h, 1.0, correction) * (h - phi) / dt
    approach = a * (c - ca.dot(n, v)) + (1 - a) * ca.dot(n, v_body - v)
    N = m * ca.fmax(approach, 0) + dt * m * ca.fmax(-ca.dot(n, g), 0)
    slip = v - v_body
    s = slip - n * ca.dot(n, slip) + SLIP * d
    F = -mu * N * s / ca.sqrt(ca.dot(s, s) + 1e-30)
    args = [x, v, *start.values(), *end.values(), h, dt, a, m, g, d, mu]
    lam, dx, dv = ca.SX.sym("lam", 3), ca.SX.sym("dx", 3), ca.SX.sym("dv", 3)
    name = f"{body_type.kind}_friction"
    return {"impulse": ca.Function(name, args, [F, N]),
            "vjp": ca.Function(f"{name}_vjp", args + [lam],
                               [ca.gradient(ca.dot(lam, F), x), ca.gradient(ca.dot(lam, F), v)]),
            "jvp": ca.Function(f"{name}_jvp", args + [dx, dv],
                               [ca.jtimes(F, ca.vertcat(x, v), ca.vertcat(dx, dv))])}


class Coulomb:
    """The stick and slide decisions of a hold over ``bodies`` (its
    :class:`~.hold.HeldBody` list) for particles of ``masses`` under ``gravity``."""

    def __init__(self, bodies, masses, gravity, correction: float, jit: bool | None):
        self.bodies, self.n = bodies, len(masses)
        self.masses, self.gravity = np.asarray(masses, float), np.asarray(gravity, float)
        self.mu = np.array([b.friction for b in bodies])
        self.kernels = [friction_kernels(type(b.body), correction) for b in bodies]
        self.mapped = [{k: MappedKernel(f, jit=jit) for k, f in kernels.items()}
                       for kernels in self.kernels]

    def _inputs(self, b, x, v, dt, held, pick, direction=None):
        particles = held.particles[pick]
        k = particles.size
        layer = self.bodies[b]
        return [x[particles], v[particles], *layer._columns(held.geometry[pick], dt, []),
                held.normal[pick, None].astype(float), self.masses[particles, None],
                np.broadcast_to(self.gravity, (k, 3)),
                held.direction[pick] if direction is None else direction,
                np.full((k, 1), self.mu[b])]

    def _each(self, held):
        for b in range(len(self.bodies)):
            pick = np.flatnonzero((held.body == b) & ~held.stick & (self.mu[b] > 0))
            if pick.size:
                yield b, pick

    def impulses(self, held, x, v, dt, direction=None):
        """``(F (k, 3), N (k,))``: every member's sliding impulse and normal impulse with
        the directions ``direction`` (default: the set's)."""
        F, N = np.zeros((held.count, 3)), np.zeros(held.count)
        for b in range(len(self.bodies)):
            pick = np.flatnonzero(held.body == b)
            if pick.size and self.mu[b] > 0:
                d = None if direction is None else direction[pick]
                out = self.mapped[b]["impulse"](*self._inputs(b, x, v, dt, held, pick, d))
                F[pick], N[pick] = out[0], out[1].ravel()
        return F, N

    def _with(self, held, x, v, dt, stick, direction) -> HeldSet:
        held = HeldSet(held.particles, held.body, held.normals, held.targets,
                       released=held.released, geometry=held.geometry, normal=held.normal,
                       stick=stick, velocity=held.velocity, direction=direction,
                       friction=np.zeros((held.count, 3)))
        F, _ = self.impulses(held, x, v, dt)
        F[stick] = 0.0
        return replace(held, friction=F)

    def decide(self, step, held, body, seen, released) -> HeldSet | None:
        """The contacts of a step: ``held`` (normal held, on ``body``), plus the free
        particles in the penalty layer of a body with friction; ``seen``: per body the
        hold's candidates ``(phi, normals, targets, velocities, rows)``."""
        body = body.copy()
        depth = np.full(self.n, np.inf)
        for b, layer in enumerate(self.bodies):
            if layer.friction > 0 and layer.penalty:
                gap = seen[b][0] - layer.body.contact.thickness
                inside = (gap < 0) & step.free & ~held & ~released & (gap < depth)
                depth[inside], body[inside] = gap[inside], b
        particles = np.flatnonzero(held | np.isfinite(depth))
        if not particles.size:
            return None
        fields = self._fields(seen, body, particles)
        mu = self.mu[body[particles]]
        slip = _tangent(fields["normals"], step.v[particles] - fields["velocity"])
        speed = np.linalg.norm(slip, axis=1)
        slide = (speed > SLIP) & (mu > 0)
        direction = slip / np.maximum(speed, 1e-300)[:, None]
        members = HeldSet(particles, body[particles], fields["normals"], fields["targets"],
                          released=released, geometry=fields["rows"], normal=held[particles],
                          stick=(mu > 0) & ~slide, velocity=fields["velocity"])
        return self._with(members, step.x, step.v, step.dt, members.stick, direction)

    def _fields(self, seen, body, particles):
        """The candidates' normals, targets, body velocities and geometry rows of
        ``particles``, each from its ``body``."""
        k = particles.size
        width = max(s[4].shape[1] for s in seen)
        out = {"normals": np.zeros((k, 3)), "targets": np.zeros(k), "velocity": np.zeros((k, 3)),
               "rows": np.zeros((k, width))}
        for b, (_, normal, target, velocity, rows) in enumerate(seen):
            mine = body[particles] == b
            if not mine.any():
                continue
            p = particles[mine]
            out["normals"][mine], out["targets"][mine] = normal[p], target[p]
            if velocity is not None:
                out["velocity"][mine] = velocity[p]
            out["rows"][mine, :rows.shape[1]] = rows[p]
        return out

    def revise(self, found, end, late, body) -> HeldSet | None:
        """``found`` with the ``late`` particles held (on ``body``, sticking where the body
        has friction) and the Coulomb checks of the solve it follows; None if none changes."""
        changed = False
        if found is not None and found.residual is not None:
            found, changed = self._checked(found, end)
        if late.size:
            found = self._joined(found, end, late, body)
            changed = True
        return found if changed else None

    def _checked(self, held, end):
        x, v, dt = end.x, end.v, end.dt
        r_t = _tangent(held.normals, held.residual)
        size = np.linalg.norm(r_t, axis=1)
        onset = -r_t / np.maximum(size, 1e-300)[:, None]
        _, N = self.impulses(held, x, v, dt, np.where(held.stick[:, None], onset,
                                                      held.direction))
        leaves = held.stick & (size > self.mu[held.body] * N * (1 + 1e-9) + 1e-15)
        slip = _tangent(held.normals, (end.x1 - x)[held.particles] / dt - held.velocity)
        sliding = ~held.stick & (self.mu[held.body] > 0)
        turned = sliding & (np.einsum("ka,ka->k", held.friction, slip) > 0)
        if not (leaves.any() or turned.any()):
            return held, False
        direction = np.where(leaves[:, None], onset, held.direction)
        return self._with(held, x, v, dt, (held.stick & ~leaves) | turned, direction), True

    def _joined(self, held, end, late, body):
        """``held`` with the normals of ``late`` held (members already or new ones)."""
        seen = [layer.candidates(end.x, end.v, end.t, end.dt) for layer in self.bodies]
        new = self._fields(seen, body, late)
        mu = self.mu[body[late]]
        parts = {"particles": late, "body": body[late], "normals": new["normals"],
                 "targets": new["targets"], "geometry": new["rows"],
                 "normal": np.ones(late.size, bool), "stick": mu > 0,
                 "velocity": new["velocity"], "direction": np.zeros((late.size, 3))}
        released = np.zeros(self.n, bool)
        if held is not None:
            keep = ~np.isin(held.particles, late)
            parts = {k: np.concatenate([getattr(held, k)[keep], a]) for k, a in parts.items()}
            order = np.argsort(parts["particles"])
            parts = {k: a[order] for k, a in parts.items()}
            released = held.released.copy()
            released[late] = False
        members = HeldSet(**parts, released=released)
        return self._with(members, end.x, end.v, end.dt, members.stick, members.direction)

    def vjp(self, x, v, dt, held, lam):
        """``(gx, gv)``, gradients of ``lam . F`` (``lam`` ``(n, 3)``, the multiplier of the
        step's right-hand side)."""
        gx, gv = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for b, pick in self._each(held):
            p = held.particles[pick]
            gx[p], gv[p] = self.mapped[b]["vjp"](*self._inputs(b, x, v, dt, held, pick), lam[p])
        return gx, gv

    def jvp(self, x, v, dt, held, dx, dv):
        """The derivative of the sliding impulses along ``(dx, dv)``, ``(n, 3)``."""
        out = np.zeros((self.n, 3))
        for b, pick in self._each(held):
            p = held.particles[pick]
            out[p] = self.mapped[b]["jvp"](*self._inputs(b, x, v, dt, held, pick), dx[p],
                                           dv[p])[0]
        return out

    def parameters(self, found) -> np.ndarray:
        """The flags ``normal``, ``stick`` and ``slide`` (0/1 per particle) and the slide
        directions ``(n, 3)``, flat, for the symbolic step."""
        flags, direction = np.zeros((3, self.n)), np.zeros((self.n, 3))
        if found is not None:
            flags[0, found.particles] = found.normal
            flags[1, found.particles] = found.stick
            flags[2, found.particles] = ~found.stick & (self.mu[found.body] > 0)
            direction[found.particles] = found.direction
        return np.concatenate([flags.ravel(), direction.ravel()])

    def symbolic(self, D, size: int):
        """``(normal, stick, slide, direction)`` (``1 x n`` each, the last ``3 x n``) from the
        hold's decision parameters D of ``size`` entries (:meth:`parameters` last)."""
        n = self.n
        tail = D[size - 6 * n:size]
        return (ca.reshape(tail[:n], 1, n), ca.reshape(tail[n:2 * n], 1, n),
                ca.reshape(tail[2 * n:3 * n], 1, n), ca.reshape(tail[3 * n:], 3, n))

    def symbolic_impulses(self, b, X, V, columns, dt, flags):
        """The sliding impulses on body b, ``3 x n``, from the hold's geometry ``columns``."""
        n = X.shape[1]
        normal, _, slide, direction = flags
        F, _ = self.kernels[b]["impulse"].map(n)(
            X, V, *columns, normal, ca.DM(self.masses).T, ca.repmat(ca.DM(self.gravity), 1, n),
            direction, ca.repmat(ca.DM(self.mu[b]), 1, n))
        return ca.repmat(slide, 3, 1) * F
