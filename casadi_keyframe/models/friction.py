r"""Coulomb friction through the step's hold: stick holds, slide pushes with a lagged bound.

A particle in contact with a body of friction ``mu`` (held on it, or inside the penalty
springs' layer) either **sticks**: the hold prescribes its tangential velocity, the body's
surface velocity there (rotation included), through the same filter that holds its normal;
or **slides**: it gets the impulse ``F = mu N d``, ``N`` its normal impulse over the step
(the hold's plus the penalty springs') and ``d`` a unit tangent, both **lagged**: taken from
the solve the decision follows and constant in the step (as IPC lags the normal force and
the tangent basis).  Every contact starts a step sticking, except one that was sliding at the
last step's end: it slides on, ``N`` the last step's and ``d`` against its relative
tangential velocity.  After a solve, a sticking particle whose tangential impulse ``r_t``
leaves the cone (``|r_t| > mu N``) slides with ``d = r_t / |r_t|`` (at the switch the two
laws give the same step), and a sliding one whose relative tangential velocity at the
step's end points along ``F`` (friction turned it) sticks; the step is solved again
(:meth:`~.interaction.Interaction.revise`).

The discrete law differentiated is the step with its modes, ``N`` and ``d`` fixed: exact
within a mode, as DiffCloth's; at a stick/slide switch the simulated map is continuous and
its derivative is the one-sided derivative of the mode the step chose.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .held_set import HeldSet

SLIP = 1e-6  # m/s: a relative tangential speed below this is no slide to go on with


def _tangent(normals, a):
    return a - normals * np.einsum("ka,ka->k", normals, a)[:, None]


class Coulomb:
    """The stick and slide decisions of a hold over ``bodies`` (its
    :class:`~.hold.HeldBody` list) for ``n`` particles."""

    def __init__(self, bodies, n: int):
        self.bodies, self.n = bodies, n
        self.mu = np.array([b.friction for b in bodies])

    def _support(self, body, phi, dt):
        """The penalty springs' normal impulse over the step (without their damping)."""
        contact = body.body.contact
        p = contact.thickness - phi
        ramp = np.where(p <= 0, 0.0, np.where(p <= contact.width, p ** 2 / (2 * contact.width),
                                                p - contact.width / 2))
        return dt * contact.stiffness * ramp if body.penalty else np.zeros_like(phi)

    def decide(self, step, held, body, seen, released, carried) -> HeldSet | None:
        """The contacts of a step: ``held`` (normal held, on ``body``), plus the free
        particles in the penalty layer of a body with friction; ``seen``: per body the
        hold's candidates ``(phi, normals, targets, velocities, rows)``."""
        n = self.n
        member, normal = held.copy(), held.copy()
        body = body.copy()
        depth = np.full(n, np.inf)
        for b, layer in enumerate(self.bodies):
            if layer.friction > 0 and layer.penalty:
                gap = seen[b][0] - layer.body.contact.thickness
                inside = (gap < 0) & step.free & ~held & ~released & (gap < depth)
                depth[inside], body[inside] = gap[inside], b
        member |= np.isfinite(depth)
        particles = np.flatnonzero(member)
        if not particles.size:
            return None
        fields = self._fields(seen, body, particles, step.dt)
        slide = np.zeros(particles.size, bool)
        friction = np.zeros((particles.size, 3))
        mu = self.mu[body[particles]]
        if carried is not None and len(carried) > 2:
            before = np.zeros(n)
            before[carried[2]] = carried[3] + 1.0  # marks the sliding ones
            was = before[particles] > 0
            slip = _tangent(fields["normals"], step.v[particles] - fields["velocity"])
            speed = np.linalg.norm(slip, axis=1)
            slide = was & (speed > SLIP) & (mu > 0)
            force = mu * (np.maximum(before[particles] - 1.0, 0) + fields["support"])
            friction[slide] = -(force / np.maximum(speed, SLIP))[slide, None] * slip[slide]
        return HeldSet(particles, body[particles], fields["normals"], fields["targets"],
                       released=released, geometry=fields["rows"], normal=normal[particles],
                       stick=(mu > 0) & ~slide, velocity=fields["velocity"], friction=friction,
                       support=fields["support"])

    def _fields(self, seen, body, particles, dt):
        """The candidates' normals, targets, body velocities, geometry rows and penalty
        support of ``particles``, each from its ``body``."""
        k = particles.size
        width = max(s[4].shape[1] for s in seen)
        out = {"normals": np.zeros((k, 3)), "targets": np.zeros(k), "velocity": np.zeros((k, 3)),
               "rows": np.zeros((k, width)), "support": np.zeros(k)}
        for b, (phi, normal, target, velocity, rows) in enumerate(seen):
            mine = body[particles] == b
            if not mine.any():
                continue
            p = particles[mine]
            out["normals"][mine], out["targets"][mine] = normal[p], target[p]
            if velocity is not None:
                out["velocity"][mine] = velocity[p]
            out["rows"][mine, :rows.shape[1]] = rows[p]
            out["support"][mine] = self._support(self.bodies[b], phi[p], dt)
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
        mu = self.mu[held.body]
        normal_force = np.where(held.normal, np.maximum(held.impulse, 0), 0) + held.support
        r_t = _tangent(held.normals, held.residual)
        size = np.linalg.norm(r_t, axis=1)
        bound = mu * normal_force
        leaves = held.stick & (size > bound * (1 + 1e-9) + 1e-15)
        v1 = (end.x1 - end.x)[held.particles] / end.dt
        slip = _tangent(held.normals, v1 - held.velocity)
        turned = ~held.stick & (mu > 0) & (np.einsum("ka,ka->k", held.friction, slip) > 0)
        if not (leaves.any() or turned.any()):
            return held, False
        friction = held.friction.copy()
        friction[leaves] = (bound / np.maximum(size, 1e-300))[leaves, None] * r_t[leaves]
        friction[turned] = 0.0
        stick = (held.stick & ~leaves) | turned
        return HeldSet(held.particles, held.body, held.normals, held.targets,
                       released=held.released, geometry=held.geometry, normal=held.normal,
                       stick=stick, velocity=held.velocity, friction=friction,
                       support=held.support), True

    def _joined(self, held, end, late, body):
        """``held`` with the normals of ``late`` held (members already or new ones)."""
        seen = [layer.candidates(end.x, end.v, end.t, end.dt) for layer in self.bodies]
        new = self._fields(seen, body, late, end.dt)
        mu = self.mu[body[late]]
        if held is None:
            released = np.zeros(self.n, bool)
            return HeldSet(late, body[late], new["normals"], new["targets"], released=released,
                           geometry=new["rows"], normal=np.ones(late.size, bool),
                           stick=mu > 0, velocity=new["velocity"],
                           friction=np.zeros((late.size, 3)), support=new["support"])
        keep = ~np.isin(held.particles, late)
        parts = {"particles": (held.particles[keep], late), "body": (held.body[keep], body[late]),
                 "normals": (held.normals[keep], new["normals"]),
                 "targets": (held.targets[keep], new["targets"]),
                 "geometry": (held.geometry[keep], new["rows"]),
                 "normal": (held.normal[keep], np.ones(late.size, bool)),
                 "stick": (held.stick[keep], mu > 0),
                 "velocity": (held.velocity[keep], new["velocity"]),
                 "friction": (held.friction[keep], np.zeros((late.size, 3))),
                 "support": (held.support[keep], new["support"])}
        order = np.argsort(np.concatenate(parts["particles"]))
        merged = {k: np.concatenate(v)[order] for k, v in parts.items()}
        released = held.released.copy()
        released[late] = False
        return HeldSet(**merged, released=released)

    def carry(self, found: HeldSet) -> tuple:
        """The particles sliding at the step's end and their hold's normal impulses."""
        slide = ~found.stick & (self.mu[found.body] > 0)
        impulse = np.where(found.normal, np.maximum(found.impulse, 0), 0)
        return found.particles[slide], impulse[slide]

    def parameters(self, found) -> np.ndarray:
        """The flags ``normal`` and ``stick`` (0/1 per particle) and the sliding impulses
        ``(n, 3)``, flat, for the symbolic step."""
        normal, stick, friction = np.zeros(self.n), np.zeros(self.n), np.zeros((self.n, 3))
        if found is not None:
            normal[found.particles] = found.normal
            stick[found.particles] = found.stick
            friction[found.particles] = found.friction
        return np.concatenate([normal, stick, friction.ravel()])

    def symbolic(self, D, size: int):
        """``(normal 1 x n, stick 1 x n, friction 3 x n)`` from the hold's decision
        parameters D (of ``size`` entries, :meth:`parameters` last)."""
        n = self.n
        tail = D[size - 5 * n:size]
        return (ca.reshape(tail[:n], 1, n), ca.reshape(tail[n:2 * n], 1, n),
                ca.reshape(tail[2 * n:], 3, n))
