r"""Coulomb friction, a tangential law of the hold (:mod:`.tangential`): stick holds, slide
pushes.

A sliding contact gets the impulse

    F = -mu N s / |s|,   s = T (v - v_body)

with ``N`` the normal impulse of :func:`~.tangential.tangential_kernels` and ``T = I - n
n^T``, smoothed below :data:`~.tangential.SLIP`-scale slips and linearized in the step's
velocity change by the seam (:mod:`.tangential`), so the slide's direction follows the slip
the step makes.  A contact starts a step sliding if it slips, else sticking; after a solve a
sticking particle whose tangential impulse ``r_t`` leaves the cone (``|r_t| > mu N``)
slides, and a sliding one whose slide overshot sticks (:mod:`.stick_slide`).  The gradient
is that of the modes the step chose, exact within them: every quantity of F is a function
of the step's start state and is differentiated.

This file is the whole law: a new one (anisotropic friction, say) is a file like it, a
:class:`~.tangential.TangentialLaw` given to a body as ``Contact(friction=...)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .tangential import TangentialLaw


@dataclass(frozen=True)
class Coulomb(TangentialLaw):
    """Coulomb's law with coefficient ``mu`` (0: frictionless); ``Contact(friction=mu)``
    takes this law."""

    mu: float = 0.0

    name = "coulomb"
    COEFFICIENTS = {"mu": 1}

    def __post_init__(self):
        if not (np.isfinite(self.mu) and self.mu >= 0):
            raise ValueError(f"Coulomb's mu must be non-negative and finite, got {self.mu}")

    @property
    def acts(self) -> bool:
        return self.mu > 0

    @staticmethod
    def impulse(N, slip, normal, mu):
        return -mu * N * slip / ca.sqrt(ca.dot(slip, slip) + 1e-30)

    def leaves(self, tangential, N):
        return np.linalg.norm(tangential, axis=1) > self.mu * N * (1 + 1e-9) + 1e-15
