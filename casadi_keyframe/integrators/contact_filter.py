r"""The implicit step's filter for contacts (Baraff and Witkin): the linear solve with the
contact particles' normal velocities prescribed, forward, backward and tangent.

With the step matrix A, its right-hand side b and the contacts' projector ``P`` (``n n^T``
on each contact particle, :class:`~casadi_keyframe.models.contact_constraint.Contacts`),
``S = I - P``, the step solves

    S (A dv - b) = 0,    P (dv - z) = 0,    z = n (c - n . v)

as ``dv = z + y`` with ``A_hat y = S (b - A z)``, ``A_hat = S A S + M P``: symmetric
positive definite like A, with A's sparsity (the pattern's blocks projected, see
:meth:`~casadi_keyframe.models.blocks.BlockPattern.projected`), so the same factorisation
serves the forward, backward and tangent solves.  ``r = A dv - b = n impulse`` on the
contacts is the constraint's impulse.

Backward (the cotangent ``w`` of dv): ``mu = A_hat^-1 S w`` and ``lam = mu + P (w - A mu)``
solve ``(S A + P)^T lam = w``; ``mu`` takes the place of the unconstrained step's
multiplier, and ``lam`` with ``q = (dv - z) - r`` weighs the normals' and targets'
derivatives.  Tangent: with ``g`` the derivative of the residual's right side,
``d(dv) = P g + A_hat^-1 S (g - A P g)``.
"""
from __future__ import annotations

import numpy as np


def projected_matrix(pattern, values, product, contacts, masses):
    """``(values, product)`` of ``A_hat = S A S + M P``: its CSC data in ``pattern`` (A's
    data ``values`` projected) and its product with a flat vector (from A's ``product``)."""
    n = masses.size
    projector = contacts.projector(n)
    touched = np.zeros(n, bool)
    touched[contacts.particles] = True
    data = pattern.projected(values, projector, touched, masses)
    mass = np.repeat(masses, 3)

    def hat(y):
        s = contacts.tangential_part(y).ravel()
        return (contacts.tangential_part(product(s)).ravel()
                + mass * contacts.normal_part(y).ravel())

    return data, hat


def constrained_rhs(contacts, b, product, z_prescribed, v, free):
    """``(rhs, z)``: the projected right-hand side ``S (b - A z)`` and the prescribed part
    ``z`` of dv (the contacts' normal parts on free components, ``z_prescribed`` on the
    pinned and attached ones), all flat."""
    z = np.where(free, contacts.prescribed(v).ravel(), z_prescribed)
    return contacts.tangential_part(b - product(z)).ravel(), z


def impulses(contacts, residual):
    """The constraint's impulse along each contact's normal from ``A dv - b`` (flat)."""
    r = residual.reshape(-1, 3)[contacts.particles]
    return np.einsum("ka,ka->k", contacts.normals, r)


def adjoint_multiplier(contacts, mu, w, product):
    """``lam = mu + P (w - A mu)`` (flat), with ``mu = A_hat^-1 S w``."""
    return mu + contacts.normal_part(w - product(mu)).ravel()


def contact_q(contacts, dv, v):
    """``q = (dv - z) - r`` on the contact particles, ``(k, 3)``."""
    dv = dv.reshape(-1, 3)
    k = contacts.particles
    z = contacts.prescribed(v)[k]
    return dv[k] - z - contacts.normals * contacts.impulse[:, None]
