r"""The hold's stick and slide decisions on bodies with a tangential law (:mod:`.tangential`).

A particle in contact with such a body (held on it, or inside the penalty springs' layer)
sticks or slides (:class:`~.held_set.HeldSet`'s ``stick``).  A contact starts a step sliding
if it slips (faster than :data:`~.tangential.SLIP` against the body's surface), else
sticking.  After a solve a sticking particle whose tangential impulse ``r_t`` leaves the
law's stick region (:meth:`~.tangential.TangentialLaw.leaves`) slides, and a sliding one
whose impulse pushed it along its slip by the step's end (the slide overshot: it would have
stopped) sticks, unless it left a stick within the step; the step is solved again.  So each
particle switches at most twice per step and the decisions settle.  The sliding impulses,
their matrices and their derivatives are the laws' kernels
(:func:`~.tangential.tangential_kernels`), body by body: every one a function of the
step's start state, so the decisions are the only thing the derivative holds.
"""
from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np

from ...kernels import MappedKernel
from .friction import Coulomb
from .held_set import HeldSet
from .tangential import SLIP, TangentialLaw, tangential_kernels


def tangential_law(contact) -> TangentialLaw | None:
    """The law of a :class:`~.colliders.Contact`'s ``friction`` (a number is Coulomb's mu),
    None if it does not act."""
    law = contact.friction
    law = law if isinstance(law, TangentialLaw) else Coulomb(float(law))
    return law if law.acts else None


def _tangent(normals, a):
    return a - normals * np.einsum("ka,ka->k", normals, a)[:, None]


class StickSlide:
    """The stick and slide decisions of a hold over ``bodies`` (its
    :class:`~.hold.HeldBody` list, each with its ``law`` or None) for particles of
    ``masses`` under ``gravity``."""

    def __init__(self, bodies, masses, gravity, correction: float, jit: bool | None):
        self.bodies, self.n = bodies, len(masses)
        self.masses, self.gravity = np.asarray(masses, float), np.asarray(gravity, float)
        self.laws = [b.law for b in bodies]
        self.acts = np.array([law is not None for law in self.laws])
        self.kernels = [None if law is None else
                        tangential_kernels(type(law), type(b.body), correction)
                        for law, b in zip(self.laws, bodies)]
        self.mapped = [None if kernels is None else
                       {k: MappedKernel(f, jit=jit) for k, f in kernels.items()}
                       for kernels in self.kernels]

    def _inputs(self, b, x, v, dt, held, pick):
        particles = held.particles[pick]
        k = particles.size
        layer = self.bodies[b]
        coefficients = [np.full((k, c.size), c) for c in self.laws[b].coefficients()]
        return [x[particles], v[particles], *layer.columns(held.geometry[pick], dt, []),
                held.normal[pick, None].astype(float), self.masses[particles, None],
                np.broadcast_to(self.gravity, (k, 3)), *coefficients]

    def _each(self, held):
        for b in range(len(self.bodies)):
            pick = np.flatnonzero((held.body == b) & ~held.stick & self.acts[b])
            if pick.size:
                yield b, pick

    def impulses(self, held, x, v, dt):
        """``(F (k, 3), B (k, 3, 3), N (k,))``: every member's sliding impulse at no velocity
        change, its matrix and its normal impulse (zero off the bodies with a law)."""
        F, B, N = np.zeros((held.count, 3)), np.zeros((held.count, 3, 3)), np.zeros(held.count)
        for b in range(len(self.bodies)):
            pick = np.flatnonzero(held.body == b)
            if pick.size and self.acts[b]:
                out = self.mapped[b]["impulse"](*self._inputs(b, x, v, dt, held, pick))
                F[pick], B[pick], N[pick] = out[0], out[1].reshape(-1, 3, 3), out[2].ravel()
        return F, B, N

    def _with(self, held, x, v, dt, stick, left) -> HeldSet:
        held = HeldSet(held.particles, held.body, held.normals, held.targets,
                       released=held.released, geometry=held.geometry, normal=held.normal,
                       stick=stick, velocity=held.velocity, left=left)
        F, B, _ = self.impulses(held, x, v, dt)
        F[stick], B[stick] = 0.0, 0.0
        return replace(held, friction=F, blocks=B)

    def decide(self, step, held, body, seen, released) -> HeldSet | None:
        """The contacts of a step: ``held`` (normal held, on ``body``), plus the free
        particles in the penalty layer of a body with a law; ``seen``: per body the
        hold's candidates ``(phi, normals, targets, velocities, rows)``."""
        body = body.copy()
        depth = np.full(self.n, np.inf)
        for b, layer in enumerate(self.bodies):
            if self.acts[b] and layer.penalty:
                gap = seen[b][0] - layer.body.contact.thickness
                inside = (gap < 0) & step.free & ~held & ~released & (gap < depth)
                depth[inside], body[inside] = gap[inside], b
        particles = np.flatnonzero(held | np.isfinite(depth))
        if not particles.size:
            return None
        fields = self._fields(seen, body, particles)
        acts = self.acts[body[particles]]
        slip = _tangent(fields["normals"], step.v[particles] - fields["velocity"])
        slide = (np.linalg.norm(slip, axis=1) > SLIP) & acts
        members = HeldSet(particles, body[particles], fields["normals"], fields["targets"],
                          released=released, geometry=fields["rows"], normal=held[particles],
                          stick=acts & ~slide, velocity=fields["velocity"])
        return self._with(members, step.x, step.v, step.dt, members.stick,
                          np.zeros(particles.size, bool))

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
        has a law) and the checks of the solve it follows; None if none changes."""
        changed = False
        if found is not None and found.residual is not None:
            found, changed = self._checked(found, end)
        if late.size:
            found = self._joined(found, end, late, body)
            changed = True
        return found if changed else None

    def _leaving(self, held, r_t, N):
        """``(k,)``: the sticking members whose tangential impulse ``r_t`` leaves their law's
        stick region under the normal impulses ``N``."""
        out = np.zeros(held.count, bool)
        for b, law in enumerate(self.laws):
            pick = np.flatnonzero(held.body == b)
            if pick.size and law is not None:
                out[pick] = law.leaves(r_t[pick], N[pick])
        return held.stick & out

    def _checked(self, held, end):
        """``(held, changed)``: the sticks that leave their law's region slide, the slides
        that overshot stick (module docstring)."""
        x, v, dt = end.x, end.v, end.dt
        r_t = _tangent(held.normals, held.residual)
        _, _, N = self.impulses(held, x, v, dt)
        leaves = self._leaving(held, r_t, N)
        k = held.particles
        dv = (end.x1 - x)[k] / dt - v[k]
        slip = _tangent(held.normals, v[k] + dv - held.velocity)
        pushed = held.friction - np.einsum("kab,kb->ka", held.blocks, dv)
        sliding = ~held.stick & self.acts[held.body] & ~held.left
        turned = sliding & (np.einsum("ka,ka->k", pushed, slip) > 0)
        if not (leaves.any() or turned.any()):
            return held, False
        return self._with(held, x, v, dt, (held.stick & ~leaves) | turned,
                          held.left | leaves), True

    def _joined(self, held, end, late, body):
        """``held`` with the normals of ``late`` held (members already or new ones)."""
        seen = [layer.candidates(end.x, end.v, end.t, end.dt) for layer in self.bodies]
        new = self._fields(seen, body, late)
        parts = {"particles": late, "body": body[late], "normals": new["normals"],
                 "targets": new["targets"], "geometry": new["rows"],
                 "normal": np.ones(late.size, bool), "stick": self.acts[body[late]],
                 "velocity": new["velocity"], "left": np.zeros(late.size, bool)}
        released = np.zeros(self.n, bool)
        if held is not None:
            keep = ~np.isin(held.particles, late)
            parts = {k: np.concatenate([getattr(held, k)[keep], a]) for k, a in parts.items()}
            order = np.argsort(parts["particles"])
            parts = {k: a[order] for k, a in parts.items()}
            released = held.released.copy()
            released[late] = False
        members = HeldSet(**parts, released=released)
        return self._with(members, end.x, end.v, end.dt, members.stick, members.left)

    def vjp(self, x, v, dt, held, lam, change):
        """``(gx, gv)``, gradients of ``lam . (F - B q)`` (``lam`` ``(n, 3)``, the multiplier
        of the step's right-hand side; ``q``: the members' velocity ``change`` ``(k, 3)``,
        held)."""
        gx, gv = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for b, pick in self._each(held):
            p = held.particles[pick]
            gx[p], gv[p] = self.mapped[b]["vjp"](*self._inputs(b, x, v, dt, held, pick), lam[p],
                                                 change[pick])
        return gx, gv

    def jvp(self, x, v, dt, held, change, dx, dv):
        """The derivative of the sliding impulses ``F - B q`` along ``(dx, dv)``, ``(n, 3)``
        (``q``: the members' velocity ``change``, held)."""
        out = np.zeros((self.n, 3))
        for b, pick in self._each(held):
            p = held.particles[pick]
            out[p] = self.mapped[b]["jvp"](*self._inputs(b, x, v, dt, held, pick), change[pick],
                                           dx[p], dv[p])[0]
        return out

    def parameters(self, found) -> np.ndarray:
        """The flags ``normal``, ``stick`` and ``slide`` (0/1 per particle), flat, for the
        symbolic step."""
        flags = np.zeros((3, self.n))
        if found is not None:
            flags[0, found.particles] = found.normal
            flags[1, found.particles] = found.stick
            flags[2, found.particles] = ~found.stick & self.acts[found.body]
        return flags.ravel()

    def symbolic(self, D, size: int):
        """``(normal, stick, slide)`` (``1 x n`` each) from the hold's decision parameters D
        of ``size`` entries (:meth:`parameters` last)."""
        n = self.n
        tail = D[size - 3 * n:size]
        return tuple(ca.reshape(tail[k * n:(k + 1) * n], 1, n) for k in range(3))

    def symbolic_impulses(self, b, X, V, columns, dt, flags):
        """``(F 3 x n, B 9 x n)``: the sliding impulses on body b and their matrices
        (row-major), from the hold's geometry ``columns``."""
        n = X.shape[1]
        normal, _, slide = flags
        coefficients = [ca.repmat(ca.DM(c), 1, n) for c in self.laws[b].coefficients()]
        F, B, _ = self.kernels[b]["impulse"].map(n)(
            X, V, *columns, normal, ca.DM(self.masses).T, ca.repmat(ca.DM(self.gravity), 1, n),
            *coefficients)
        return ca.repmat(slide, 3, 1) * F, ca.repmat(slide, 9, 1) * B
