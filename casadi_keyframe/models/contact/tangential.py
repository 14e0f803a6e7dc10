r"""The seam between the step's hold and a law of a contact's tangential motion (friction).

A held contact (:mod:`.hold`) on a body with a tangential law either **sticks**: the hold
prescribes its tangential velocity, the body's surface velocity there, through the same
filter that holds its normal; or **slides**: it gets the law's impulse ``F``, a function of
the step's start state (so the solve stays symmetric and the derivative is exact).  The
stick and slide decisions are the hold's (:mod:`.stick_slide`); a law gives only what is its
own, per body:

* its **coefficients** (:attr:`TangentialLaw.COEFFICIENTS`: name -> size), numbers the
  kernels take as inputs;
* the sliding **impulse** as a CasADi expression (:meth:`TangentialLaw.impulse`) of the
  normal impulse ``N`` that stops the particle's approach over the step and carries its
  weight, the slip ``s = T (v - v_body) + SLIP d`` in the tangent plane (``d``: the
  direction a slide starts in where the slip is nil), the normal and the coefficients;
* whether a sticking contact's tangential impulse **leaves** the stick region
  (:meth:`TangentialLaw.leaves`).

:func:`tangential_kernels` lifts the impulse to per-particle kernels with their reverse and
forward derivatives, so a new law (one file: a subclass, e.g. :class:`~.friction.Coulomb`)
writes no derivative, no decision and no bookkeeping.  A body takes a law through its
:class:`~.colliders.Contact` (``friction=``).
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

SLIP = 1e-4  # m/s: the slip below which a slide leans on its decided direction d


class TangentialLaw:
    """A law of a held contact's tangential motion on one body (the module docstring says
    what it gives).  Subclasses are frozen dataclasses whose fields are the
    :attr:`COEFFICIENTS`, in that order."""

    name = "tangential law"
    COEFFICIENTS: dict[str, int] = {}

    @property
    def acts(self) -> bool:
        """Whether the law does anything (a frictionless body holds the normal only)."""
        return True

    def coefficients(self) -> list[np.ndarray]:
        """The values of :attr:`COEFFICIENTS`, each ``(size,)``."""
        return [np.atleast_1d(np.asarray(getattr(self, key), float))
                for key in self.COEFFICIENTS]

    @staticmethod
    def impulse(N, slip, normal, **coefficients):
        """The sliding impulse ``F`` (3,) in CasADi from the normal impulse ``N``, the
        tangential ``slip`` (3,), the unit ``normal`` (3,) and the coefficients' symbols."""
        raise NotImplementedError

    def leaves(self, tangential: np.ndarray, N: np.ndarray) -> np.ndarray:
        """``(k,)`` bools: the sticking contacts whose tangential impulse ``(k, 3)`` leaves
        the stick region under the normal impulses ``N`` ``(k,)``."""
        raise NotImplementedError


@functools.lru_cache(maxsize=None)
def tangential_kernels(law: type, body_type: type, correction: float) -> dict[str, ca.Function]:
    """Per particle ``(x, v, *geometry at t, *geometry at t + dt, layer, dt, a, m, g, d,
    *coefficients)``: ``impulse -> (F, N)`` with

        N = m max(a (c - n . v) + (1 - a) n . (v_body - v), 0) + dt m max(-n . g, 0)

    (``a = 1``: the normal held, to the hold's target ``c``; ``correction``: the hold's),
    ``vjp(..., lam) -> (gx, gv)`` the gradients of ``lam . F``, ``jvp(..., dx, dv) -> dF``."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    start = {key: ca.SX.sym(f"{key}_0", size) for key, size in body_type.GEOMETRY.items()}
    end = {key: ca.SX.sym(f"{key}_1", size) for key, size in body_type.GEOMETRY.items()}
    h, dt, a, m = (ca.SX.sym(s) for s in ("h", "dt", "a", "m"))
    coefficients = {key: ca.SX.sym(key, size) for key, size in law.COEFFICIENTS.items()}
    g, d = ca.SX.sym("g", 3), ca.SX.sym("d", 3)
    phi, _, _ = body_type.surface(x, **start)
    phi_end, n, v_body = body_type.surface(x, **end)
    c = (phi - phi_end) / dt + ca.if_else(phi >= h, 1.0, correction) * (h - phi) / dt
    approach = a * (c - ca.dot(n, v)) + (1 - a) * ca.dot(n, v_body - v)
    N = m * ca.fmax(approach, 0) + dt * m * ca.fmax(-ca.dot(n, g), 0)
    slip = v - v_body
    s = slip - n * ca.dot(n, slip) + SLIP * d
    F = law.impulse(N, s, n, **coefficients)
    args = [x, v, *start.values(), *end.values(), h, dt, a, m, g, d, *coefficients.values()]
    lam, dx, dv = ca.SX.sym("lam", 3), ca.SX.sym("dx", 3), ca.SX.sym("dv", 3)
    name = f"{body_type.kind}_{law.name}"
    return {"impulse": ca.Function(name, args, [F, N]),
            "vjp": ca.Function(f"{name}_vjp", args + [lam],
                               [ca.gradient(ca.dot(lam, F), x), ca.gradient(ca.dot(lam, F), v)]),
            "jvp": ca.Function(f"{name}_jvp", args + [dx, dv],
                               [ca.jtimes(F, ca.vertcat(x, v), ca.vertcat(dx, dv))])}
