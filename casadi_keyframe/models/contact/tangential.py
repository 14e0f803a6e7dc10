r"""The seam between the step's hold and a law of a contact's tangential motion (friction).

A held contact (:mod:`.hold`) on a body with a tangential law either **sticks**: the hold
prescribes its tangential velocity, the body's surface velocity there, through the same
filter that holds its normal; or **slides**: it gets the law's impulse, linearized in the
step's velocity change ``dv`` about the slip ``s = T (v - v_body)`` at the step's start
(``T = I - n n^T``), as the step linearizes every force:

    F(dv) = F_0 - B dv,   F_0 = F(s),   B = -T (dF/ds) T   (symmetrized),

so the direction of a slide turns with the slip the step makes (implicitly), while its
bound, the normal impulse ``N``, is taken at the step's start.  ``B`` joins the step's
matrix (symmetric positive semi-definite for a law that dissipates, so the solve stays a
Cholesky), ``F_0`` its right-hand side.  Every input of F and B is a function of the step's
start state and is differentiated: the derivative is exact for the step as computed.

The law's impulse is smoothed below :data:`SMOOTH` by the seam: a law gives ``F(s)`` of a
slip's direction (rate-independent, like Coulomb's ``-mu N s / |s|``), and the seam takes
the tangential part of ``F(s + SMOOTH n)``, the slip lifted off the tangent plane (for
Coulomb ``-mu N s / sqrt(|s|^2 + SMOOTH^2)``): smooth at s = 0, where a contact that starts
to slide from a stick (its slip nil) meets a stiff viscous law that lets it go within a
few steps.

The stick and slide decisions are the hold's (:mod:`.stick_slide`); a law gives only what is
its own, per body:

* its **coefficients** (:attr:`TangentialLaw.COEFFICIENTS`: name -> size), numbers the
  kernels take as inputs;
* the sliding **impulse** as a CasADi expression (:meth:`TangentialLaw.impulse`) of the
  normal impulse ``N`` that stops the particle's approach over the step and carries its
  weight, the slip ``s`` in the tangent plane, the normal and the coefficients;
* whether a sticking contact's tangential impulse **leaves** the stick region
  (:meth:`TangentialLaw.leaves`).

:func:`tangential_kernels` lifts ``F_0`` and ``B`` to per-particle kernels with their reverse
and forward derivatives, so a new law (one file: a subclass, e.g.
:class:`~.friction.Coulomb`) writes no derivative, no decision and no bookkeeping.  A body
takes a law through its :class:`~.colliders.Contact` (``friction=``).
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

SLIP = 1e-4  # m/s: a contact slipping faster than this at a step's start starts it sliding
SMOOTH = 1e-2  # m/s: the slip below which the seam smooths a law's impulse (viscous at 0)


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
        ``slip`` (3,: the seam lifts it off the tangent plane), the unit ``normal`` (3,) and
        the coefficients' symbols: a function of the slip's direction, minus the slip
        gradient of a convex dissipation (so its derivative, which joins the step's matrix,
        is symmetric negative semi-definite)."""
        raise NotImplementedError

    def leaves(self, tangential: np.ndarray, N: np.ndarray) -> np.ndarray:
        """``(k,)`` bools: the sticking contacts whose tangential impulse ``(k, 3)`` leaves
        the stick region under the normal impulses ``N`` ``(k,)``."""
        raise NotImplementedError


def smoothed(law: type, N, slip, normal, coefficients: dict):
    """The law's impulse smoothed at nil slip (module docstring), in CasADi."""
    F = law.impulse(N, slip + SMOOTH * normal, normal, **coefficients)
    return F - normal * ca.dot(normal, F)


@functools.lru_cache(maxsize=None)
def tangential_kernels(law: type, body_type: type, correction: float) -> dict[str, ca.Function]:
    """Per particle ``(x, v, *geometry at t, *geometry at t + dt, layer, dt, a, m, g,
    *coefficients)``: ``impulse -> (F_0, B, N)`` (B row-major, 9) with

        N = m max(a (c - n . v) + (1 - a) n . (v_body - v), 0) + dt m max(-n . g, 0)

    (``a = 1``: the normal held, to the hold's target ``c``; ``correction``: the hold's);
    ``vjp(..., lam, q) -> (gx, gv)`` the gradients of ``lam . (F_0 - B q)``, ``jvp(..., q, dx,
    dv) -> d(F_0 - B q)`` (q: the step's velocity change, held)."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    start = {key: ca.SX.sym(f"{key}_0", size) for key, size in body_type.GEOMETRY.items()}
    end = {key: ca.SX.sym(f"{key}_1", size) for key, size in body_type.GEOMETRY.items()}
    h, dt, a, m = (ca.SX.sym(s) for s in ("h", "dt", "a", "m"))
    coefficients = {key: ca.SX.sym(key, size) for key, size in law.COEFFICIENTS.items()}
    g = ca.SX.sym("g", 3)
    phi, _, _ = body_type.surface(x, **start)
    phi_end, n, v_body = body_type.surface(x, **end)
    c = (phi - phi_end) / dt + ca.if_else(phi >= h, 1.0, correction) * (h - phi) / dt
    approach = a * (c - ca.dot(n, v)) + (1 - a) * ca.dot(n, v_body - v)
    N = m * ca.fmax(approach, 0) + dt * m * ca.fmax(-ca.dot(n, g), 0)
    T = ca.SX.eye(3) - ca.mtimes(n, n.T)
    slip = ca.mtimes(T, v - v_body)
    sigma = ca.SX.sym("sigma", 3)
    F_sigma = smoothed(law, N, sigma, n, coefficients)
    J = ca.substitute(ca.jacobian(F_sigma, sigma), sigma, slip)
    F = ca.substitute(F_sigma, sigma, slip)
    B = -ca.mtimes([T, J, T])
    B = (B + B.T) / 2
    args = [x, v, *start.values(), *end.values(), h, dt, a, m, g, *coefficients.values()]
    lam, q, dx, dv = (ca.SX.sym(s, 3) for s in ("lam", "q", "dx", "dv"))
    pushed = F - ca.mtimes(B, q)
    name = f"{body_type.kind}_{law.name}"
    return {"impulse": ca.Function(name, args, [F, ca.vec(B.T), N]),
            "vjp": ca.Function(f"{name}_vjp", args + [lam, q],
                               [ca.gradient(ca.dot(lam, pushed), x),
                                ca.gradient(ca.dot(lam, pushed), v)]),
            "jvp": ca.Function(f"{name}_jvp", args + [q, dx, dv],
                               [ca.jtimes(pushed, ca.vertcat(x, v), ca.vertcat(dx, dv))])}
