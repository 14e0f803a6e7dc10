r"""The implicit step's solve with a held set (the hold, :mod:`~..models.contact.hold`; Baraff and
Witkin's filter), forward, backward and tangent.

With the step matrix A, its right-hand side b and the held set's projector ``P`` (``n n^T``
per held particle, :class:`~casadi_keyframe.models.contact.hold.HeldSet`), ``S = I - P``, the step
solves

    S (A dv - b) = 0,    P (dv - z) = 0,    z = n (c - n . v)

as ``dv = z + y`` with ``A_hat y = S (b - A z)``, ``A_hat = S A S + M P``: symmetric
positive definite like A, with A's sparsity (the pattern's blocks projected, see
:meth:`~casadi_keyframe.models.blocks.BlockPattern.projected`), so the same factorisation
serves the forward, backward and tangent solves.  ``r = A dv - b = n impulse`` on the held
particles is the hold's impulse.

Backward (the cotangent ``w`` of dv): ``mu = A_hat^-1 S w`` and ``lam = mu + P (w - A mu)``
solve ``(S A + P)^T lam = w``; ``mu`` takes the place of the unheld step's multiplier, and
``lam`` with ``q = (dv - z) - r`` weighs the normals' and targets' derivatives.  With
friction ``P`` also holds sticking particles' tangents, and a sliding particle's impulse,
linearized in dv as ``F - B dv`` (:mod:`~casadi_keyframe.models.contact.tangential`), puts
F into b and B into A (:func:`sliding_step`): A stands for ``A + B`` above and below, and
``r`` is the hold's own impulse.  Tangent:
with ``g`` the derivative of the residual's right side, ``d(dv) = P g + A_hat^-1 S (g - A P g)``.
"""
from __future__ import annotations

import numpy as np


def sliding_step(product, held):
    """The product ``y -> (A + B) y`` (flat) of a step whose ``held`` set slides particles
    (B: their friction's blocks), from A's ``product``; A's own without slides."""
    if held is None or not held.frictional or not held.blocks.any():
        return product
    return lambda y: product(y) + held.sliding_product(y).ravel()


def projected_matrix(pattern, values, product, held, masses):
    """``(values, product)`` of ``A_hat = S A S + M P`` (A with the slides' blocks): its CSC
    data in ``pattern`` (A's data ``values`` projected) and its product with a flat vector
    (from ``product``, the step's with the slides: :func:`sliding_step`)."""
    n = masses.size
    projector = held.projector(n)
    touched = np.zeros(n, bool)
    touched[held.particles] = True
    extra = None
    if held.frictional and held.blocks.any():
        extra = np.zeros((n, 3, 3))
        extra[held.particles] = held.blocks
    data = pattern.projected(values, projector, touched, masses, extra)
    return data, projected_product(product, held, masses)


def projected_product(product, held, masses):
    """``y -> A_hat y`` (flat) of ``A_hat = S A S + M P``, from A's ``product``."""
    mass = np.repeat(masses, 3)

    def hat(y):
        s = held.unheld_part(y).ravel()
        return held.unheld_part(product(s)).ravel() + mass * held.held_part(y).ravel()

    return hat


def held_rhs(held, b, product, z_prescribed, v, free):
    """``(rhs, z)``: the projected right-hand side ``S (b - A z)`` and the prescribed part
    ``z`` of dv (the held directions' on free components, ``z_prescribed`` on the pinned
    and attached ones), all flat."""
    z = np.where(free, held.prescribed(v).ravel(), z_prescribed)
    pushed = held.pushed(v.shape[0])
    if pushed is not None:  # sliding particles' friction at no velocity change
        b = b + pushed.ravel()
    return held.unheld_part(b - product(z)).ravel(), z


def adjoint_multiplier(held, mu, w, product):
    """``lam = mu + P (w - A mu)`` (flat), with ``mu = A_hat^-1 S w``."""
    return mu + held.held_part(w - product(mu)).ravel()


def held_q(held, dv, v):
    """``q = (dv - z) - r`` on the held particles, ``(k, 3)``."""
    dv = dv.reshape(-1, 3)
    k = held.particles
    z = held.prescribed(v)[k]
    return dv[k] - z - held.hold_residual()
