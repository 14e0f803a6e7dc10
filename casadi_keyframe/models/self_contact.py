"""Cloth self-contact as stiff repulsive springs: particles nearer than the contact's
thickness that no spring joins push each other apart with the penalty law of
:mod:`.penalty`, along the line between them."""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np
from scipy.spatial import cKDTree

from ..kernels import interaction_kernels
from .colliders import Contact
from .interaction import PairInteraction
from .penalty import penalty_law


@functools.lru_cache(maxsize=None)
def self_contact_kernels() -> dict[str, ca.Function]:
    """Self-contact of particles i and j, ``(d = x_j - x_i, dv = v_j - v_i, gains) -> f_i``."""
    d, dv, gains = ca.SX.sym("d", 3), ca.SX.sym("dv", 3), ca.SX.sym("gains", 4)
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    # i is pushed along -d/r, away from j; the velocity of i relative to j is -dv
    return interaction_kernels("self_contact", d, dv, [gains],
                               *penalty_law(r, -d / r, -dv, gains, d))


class SelfContact(PairInteraction):
    """Repulsion between cloth particles nearer than ``contact.thickness`` and not joined by
    a spring; ``excluded`` is the (P, 2) array of joined pairs.  The pairs are found with a
    k-d tree once per state (:meth:`find`)."""

    name = "self-contact"
    role = "contact"
    fixed_pairs = False

    def __init__(self, contact: Contact, excluded: np.ndarray, n: int,
                 jit: bool | None = None):
        super().__init__(self_contact_kernels(), n, jit)
        self.contact = contact
        e = np.sort(np.asarray(excluded, dtype=np.int64), axis=1)
        self._excluded = np.unique(e[:, 0] * n + e[:, 1])

    def find(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays ``(i, j)``, i < j, of unjoined particles within the thickness."""
        found = cKDTree(x).query_pairs(self.contact.thickness, output_type="ndarray")
        if found.size == 0:
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        found = np.sort(found, axis=1)
        keep = ~np.isin(found[:, 0].astype(np.int64) * self.n + found[:, 1], self._excluded)
        return found[keep, 0].astype(np.intp), found[keep, 1].astype(np.intp)

    def pairs(self, found):
        return None if found is None or found[0].size == 0 else found

    def pair_parameters(self, i, j, found=None):
        return [np.broadcast_to(self.contact.gains, (i.size, 4))]

    def all_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every unjoined pair (for the symbolic, small-system route)."""
        i, j = np.triu_indices(self.n, 1)
        keep = ~np.isin(i.astype(np.int64) * self.n + j, self._excluded)
        return i[keep], j[keep]
