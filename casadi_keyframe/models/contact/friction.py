r"""Coulomb friction, a tangential law of the hold (:mod:`.tangential`): stick holds, slide
pushes.

A sliding contact gets the impulse

    F = -mu N t,   t = unit(T (v - v_body) + SLIP d)

with ``N`` the normal impulse of :func:`~.tangential.tangential_kernels` and ``T = I - n
n^T``.  A contact starts a step sliding if it slips (faster than
:data:`~.tangential.SLIP` against the body's surface), else sticking.  After a solve a
sticking particle whose tangential impulse ``r_t`` leaves the cone (``|r_t| > mu N``) slides
(``d = -r_t / |r_t|``), and a sliding one whose slip turned against ``t`` by the step's end
sticks; the step is solved again (:mod:`.stick_slide`).  The gradient is that of the modes
the step chose: exact within them (as DiffCloth's), one-sided at a stick/slide switch, where
the simulated map is continuous only up to the difference between ``r_t``'s direction and
``t``.

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
