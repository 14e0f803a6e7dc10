r"""The held set: what the step's hold (:mod:`.hold`) decided for one step.

Each particle in it is held on one body.  Without friction its velocity along the body's
normal ``n`` is prescribed (``P = n n^T``).  With friction (:mod:`.tangential`) each particle
also has a mode: ``normal`` (its normal velocity held, as without friction) and ``stick``
(its tangential velocity held to the body's surface velocity, ``T = I - n n^T``), so
``P = stick I + (normal - stick) n n^T``; a sliding particle gets the law's impulse
linearized in its velocity change, ``friction - blocks dv`` (:mod:`.tangential`: both
functions of the step's start state), whose ``blocks`` join the step's matrix.  The
prescribed change of velocity is

    z = normal n (c - n . v) + stick T (v_body - v)

with ``c`` the normal target (:mod:`.hold`) and ``v_body`` the body's surface velocity at the
particle at the step's end.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np


@dataclass(frozen=True)
class HeldSet:
    """The particles a step holds: ``particles`` ``(k,)`` (sorted), the ``body`` each is held
    on (index into the hold's bodies), their unit ``normals`` ``(k, 3)`` and target normal
    velocities ``targets`` ``(k,)`` at the step's start; after the solve, ``impulse``
    ``(k,)`` along each normal (negative: the hold pulled); ``released`` ``(n,)``, the
    particles let go.  ``geometry`` ``(k, g)``: each particle's body geometry at the step's
    start and end, as the hold's kernels took it.  With friction (else None): ``normal`` and
    ``stick`` ``(k,)`` bools, ``velocity`` ``(k, 3)`` the body's surface velocity,
    ``friction`` ``(k, 3)`` and ``blocks`` ``(k, 3, 3)`` the sliding impulse at no velocity
    change and its matrix (zero where a particle sticks), ``left`` ``(k,)`` the particles
    that left a stick within the step (they stick no more in it) and, after the solve,
    ``residual`` ``(k, 3)``, the hold's whole impulse."""

    particles: np.ndarray
    body: np.ndarray
    normals: np.ndarray
    targets: np.ndarray
    impulse: np.ndarray | None = None
    released: np.ndarray | None = None
    geometry: np.ndarray | None = None
    normal: np.ndarray | None = None
    stick: np.ndarray | None = None
    velocity: np.ndarray | None = None
    friction: np.ndarray | None = None
    blocks: np.ndarray | None = None
    left: np.ndarray | None = None
    residual: np.ndarray | None = None

    @property
    def count(self) -> int:
        return int(self.particles.size)

    @property
    def frictional(self) -> bool:
        return self.stick is not None

    def _weights(self):
        """``(a, b)``: ``P = b I + (a - b) n n^T`` per particle, as floats ``(k, 1)``."""
        a, b = self.normal.astype(float), self.stick.astype(float)
        return (a - b)[:, None], b[:, None]

    def projector(self, n: int) -> np.ndarray:
        """``P`` as ``(n, 3, 3)`` blocks (zero off the held particles)."""
        P = np.zeros((n, 3, 3))
        P[self.particles] = np.einsum("ka,kb->kab", self.normals, self.normals)
        if self.frictional:
            a, b = self._weights()
            P[self.particles] = (a[:, :, None] * P[self.particles]
                                 + b[:, :, None] * np.eye(3)[None])
        return P

    def held_part(self, y: np.ndarray) -> np.ndarray:
        """``P y`` for ``y`` of shape ``(n, 3)`` (flat accepted)."""
        y = np.asarray(y).reshape(-1, 3)
        out = np.zeros_like(y)
        nk, yk = self.normals, y[self.particles]
        along = nk * np.einsum("ka,ka->k", nk, yk)[:, None]
        if self.frictional:
            a, b = self._weights()
            along = a * along + b * yk
        out[self.particles] = along
        return out

    def unheld_part(self, y: np.ndarray) -> np.ndarray:
        """``S y = y - P y``."""
        y = np.asarray(y).reshape(-1, 3)
        return y - self.held_part(y)

    def prescribed(self, v: np.ndarray) -> np.ndarray:
        """``z``: the change of velocity the step makes along the held directions, ``(n, 3)``
        (zero off the held particles; module docstring)."""
        out = np.zeros_like(v)
        nk, vk = self.normals, v[self.particles]
        z = nk * (self.targets - np.einsum("ka,ka->k", nk, vk))[:, None]
        if self.frictional:
            slip = self.velocity - vk
            tangent = slip - nk * np.einsum("ka,ka->k", nk, slip)[:, None]
            z = self.normal[:, None] * z + self.stick[:, None] * tangent
        out[self.particles] = z
        return out

    def pushed(self, n: int) -> np.ndarray | None:
        """The sliding particles' friction impulses as ``(n, 3)`` (None without friction)."""
        if not self.frictional:
            return None
        out = np.zeros((n, 3))
        out[self.particles] = self.friction
        return out

    def sliding_product(self, y: np.ndarray) -> np.ndarray | None:
        """The sliding particles' matrix times ``y`` ``(n, 3)`` (flat accepted), ``(n, 3)``;
        None without friction."""
        if not self.frictional:
            return None
        y = np.asarray(y).reshape(-1, 3)
        out = np.zeros_like(y)
        out[self.particles] = np.einsum("kab,kb->ka", self.blocks, y[self.particles])
        return out

    def change(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The members' velocity change ``(k, 3)`` from the solved step's ``q = (dv - z) - r``
        (:func:`~...integrators.held_solve.held_q`) at start velocities ``v``."""
        return q + self.prescribed(v)[self.particles] + self.hold_residual()

    def solved(self, residual: np.ndarray) -> "HeldSet":
        """The same set with the impulses of a solved step, from ``A dv - b`` (flat)."""
        r = residual.reshape(-1, 3)[self.particles]
        if self.frictional:
            r = r - self.friction
            return replace(self, impulse=np.einsum("ka,ka->k", self.normals, r), residual=r)
        return replace(self, impulse=np.einsum("ka,ka->k", self.normals, r))

    def pulled(self, slack=0.0) -> np.ndarray:
        """``(k,)`` bools: the members whose normal the solved step held by pulling them onto
        the body, with an impulse below ``-slack`` (per member or one for all)."""
        pulled = self.impulse < -np.asarray(slack)
        return pulled & self.normal if self.frictional else pulled

    def without(self, drop: np.ndarray, n: int) -> "HeldSet":
        """The set less the members ``drop`` (``(k,)`` bools), which join ``released``
        (``(n,)`` over the ``n`` particles)."""
        released = np.zeros(n, bool) if self.released is None else self.released.copy()
        released[self.particles[drop]] = True
        sliced = {f.name: getattr(self, f.name)[~drop] for f in fields(self)
                  if f.name != "released" and getattr(self, f.name) is not None}
        return replace(self, **sliced, released=released)

    def hold_residual(self) -> np.ndarray:
        """The hold's impulse on each held particle, ``(k, 3)``."""
        if self.frictional:
            return self.residual
        return self.normals * self.impulse[:, None]


NOTHING_HELD = HeldSet(np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros((0, 3)),
                       np.zeros(0))
