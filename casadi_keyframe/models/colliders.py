r"""Collisions as stiff repulsive springs (section 6.1): analytic bodies and cloth self-contact.

A particle closer than ``thickness`` to a body's surface (signed distance ``phi``) feels a
push along the surface normal ``n`` with penetration ``p = thickness - phi``:

    f = stiffness * ramp(p) * n  -  damping * min(p / width, 1) * ((v - v_body) . n) n

``ramp(p) = p^2 / (2 width)`` for ``0 <= p <= width`` and ``p - width / 2`` beyond, zero for
``p < 0``: the force and its stiffness are continuous when contact starts, so the linearized
implicit step (whose matrix holds the stiffness) does not jump as particles touch.  The
stiffness K the step uses acts along the normal only (the surface's curvature term is left
out, see :func:`penalty_law`), so it is symmetric and negative semi-definite; as for the
springs, the damping's position derivative is left out of K.

Bodies: :class:`Plane`, :class:`Sphere`, :class:`Capsule` (a segment swept by a sphere).
Any point given may be a function of time ``t -> (3,)`` so the body moves along a path; its
velocity is the central difference of that path.  :class:`SelfContact` pushes apart cloth
particles nearer than ``thickness`` that no spring joins (found with a k-d tree each step).

Each body's law is one SX expression per particle ``(x, v, geometry..., gains) -> f``, lifted
to force, Jacobian-block and adjoint kernels by :func:`interaction_kernels` and mapped over
the particles; its Jacobian blocks are 3x3 and diagonal per particle.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.spatial import cKDTree

from ..kernels import interaction_kernels, pair_difference


@dataclass(frozen=True)
class Contact:
    """Penalty law shared by bodies: ``stiffness`` N/m, ``damping`` N s/m, ``thickness`` m
    (the gap kept to the surface) and ``width`` m (penetration over which stiffness ramps up)."""

    stiffness: float = 2000.0
    damping: float = 1.0
    thickness: float = 0.01
    width: float = 0.005

    def __post_init__(self):
        for name in ("stiffness", "damping", "thickness", "width"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"Contact.{name} must be non-negative and finite, got {value}")
        if self.width <= 0:
            raise ValueError(f"Contact.width must be positive, got {self.width}")

    @property
    def gains(self) -> np.ndarray:
        return np.array([self.stiffness, self.damping, self.thickness, self.width])


def penalty_law(phi, normal, rel_v, gains, x):
    """``(f, K)`` (SX) of a contact with signed distance ``phi`` (a function of ``x``), unit
    ``normal`` and relative velocity ``rel_v``: the force and the stiffness the implicit step
    uses, ``K = -stiffness ramp'(p) normal grad(phi)^T``.

    K leaves out ``ramp(p) d(normal)/dx``, the surface's curvature: for a sphere or capsule
    it pushes particles apart sideways, and with it the step matrix loses positive
    definiteness (as for compressed springs, see :func:`.cloth.spring_law`).
    """
    k, c, h, s = (gains[i] for i in range(4))
    p = h - phi
    ramp = ca.if_else(p <= 0, 0, ca.if_else(p <= s, p ** 2 / (2 * s), p - s / 2))
    active = ca.fmin(ca.fmax(p / s, 0), 1)  # ramp'(p)
    force = k * ramp * normal - c * active * ca.dot(rel_v, normal) * normal
    return force, -k * active * ca.mtimes(normal, ca.jacobian(phi, x))


def _body_kernels(name: str, geometry: dict, distance) -> dict[str, ca.Function]:
    """Kernels of a body; ``distance(x, **geometry) -> (phi, normal, v_body)``.  Beside the
    interaction kernels, ``distance`` gives the signed distance phi to the surface (negative
    inside the body), with the same inputs."""
    x, v = ca.SX.sym("x", 3), ca.SX.sym("v", 3)
    geo = {key: ca.SX.sym(key, size) for key, size in geometry.items()}
    gains = ca.SX.sym("gains", 4)
    phi, normal, v_body = distance(x, **geo)
    kernels = interaction_kernels(name, x, v, [*geo.values(), gains],
                                  *penalty_law(phi, normal, v - v_body, gains, x))
    kernels["distance"] = ca.Function(f"{name}_distance", [x, v, *geo.values(), gains], [phi])
    return kernels


def _point(value, name: str):
    """A fixed 3-vector or a callable path ``t -> (3,)``, validated."""
    if callable(value):
        probe = np.asarray(value(0.0), dtype=float)
        if probe.shape != (3,) or not np.all(np.isfinite(probe)):
            raise ValueError(f"{name}(t) must return 3 finite numbers, got {probe!r}")
        return value
    a = np.asarray(value, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers or a function of time, got {value!r}")
    return a


def _at(point, t: float, h: float = 1e-5):
    """Position and velocity of a fixed or moving point at time t."""
    if not callable(point):
        return point, np.zeros(3)
    p = np.asarray(point(t), dtype=float)
    return p, (np.asarray(point(t + h), float) - np.asarray(point(t - h), float)) / (2 * h)


class Body:
    """A rigid analytic collider; subclasses give the geometry and its signed distance.

    ``kernels`` are the body's per-particle SX kernels; the model that holds the body maps
    and evaluates them (:meth:`inputs` gives their inputs after ``x, v``).
    """

    kernels: dict

    def __init__(self, contact: Contact | None):
        self.contact = Contact() if contact is None else contact

    def geometry(self, t: float) -> list[np.ndarray]:
        """The kernels' geometry inputs at time t (positions, sizes, velocities)."""
        raise NotImplementedError

    def inputs(self, n: int, t: float) -> list[np.ndarray]:
        """The kernels' inputs after ``x, v`` for ``n`` particles at time t: the geometry
        and the contact gains, one row per particle."""
        columns = [np.broadcast_to(g, (n, np.size(g))) for g in self.geometry(t)]
        return columns + [np.broadcast_to(self.contact.gains, (n, 4))]

    def symbolic(self, kind: str, X, V, S) -> list:
        """Kernel ``kind`` ("force" or "jac") mapped over the ``3 x n`` particles X, V given
        this body's parameters S (a column); the kernel's outputs, one column per particle."""
        kernel, n = self.kernels[kind], X.shape[1]
        parts, at = [], 0
        for i in range(2, kernel.n_in() - 1):
            size = kernel.size1_in(i)
            parts.append(ca.repmat(S[at:at + size], 1, n))
            at += size
        gains = ca.repmat(ca.DM(self.contact.gains), 1, n)
        out = kernel.map(n)(X, V, *parts, gains)
        return list(out) if isinstance(out, (list, tuple)) else [out]

    def parameters(self, t: float) -> np.ndarray:
        """This body's geometry at time t as one flat vector (the symbolic S)."""
        return np.concatenate([np.ravel(g) for g in self.geometry(t)])


def _plane_distance(x, point, normal, velocity):
    unit = normal / ca.norm_2(normal)
    return ca.dot(x - point, unit), unit, velocity


class Plane(Body):
    """The half-space above a plane through ``point`` with upward ``normal`` (e.g. the ground)."""

    kernels = _body_kernels("plane_contact", {"point": 3, "normal": 3, "velocity": 3},
                            _plane_distance)

    def __init__(self, point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), contact=None):
        super().__init__(contact)
        self.point = _point(point, "Plane point")
        self.normal = np.asarray(normal, dtype=float)
        if self.normal.shape != (3,) or not np.isfinite(self.normal).all() or not self.normal.any():
            raise ValueError(f"Plane normal must be 3 finite numbers, not all zero, got {normal!r}"
                             " (a plane may move through its point, not turn)")

    def geometry(self, t):
        p, vp = _at(self.point, t)
        return [p, self.normal, vp]


def _sphere_distance(x, center, radius, velocity):
    d = x - center
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    return r - radius, d / r, velocity


class Sphere(Body):
    """A ball of ``radius`` about ``center`` (fixed, or a function of time)."""

    kernels = _body_kernels("sphere_contact", {"center": 3, "radius": 1, "velocity": 3},
                            _sphere_distance)

    def __init__(self, center, radius: float, contact=None):
        super().__init__(contact)
        self.center = _point(center, "Sphere center")
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"Sphere radius must be positive, got {radius}")
        self.radius = float(radius)

    def geometry(self, t):
        c, vc = _at(self.center, t)
        return [c, np.array([self.radius]), vc]


def _capsule_distance(x, a, b, radius, va, vb):
    ab = b - a
    s = ca.fmin(ca.fmax(ca.dot(x - a, ab) / (ca.dot(ab, ab) + 1e-12), 0), 1)
    d = x - (a + s * ab)
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    return r - radius, d / r, (1 - s) * va + s * vb


class Capsule(Body):
    """The points within ``radius`` of segment ``a``-``b`` (ends fixed or functions of time)."""

    kernels = _body_kernels("capsule_contact", {"a": 3, "b": 3, "radius": 1, "va": 3, "vb": 3},
                            _capsule_distance)

    def __init__(self, a, b, radius: float, contact=None):
        super().__init__(contact)
        self.a, self.b = _point(a, "Capsule end a"), _point(b, "Capsule end b")
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"Capsule radius must be positive, got {radius}")
        self.radius = float(radius)

    def geometry(self, t):
        (a, va), (b, vb) = _at(self.a, t), _at(self.b, t)
        return [a, b, np.array([self.radius]), va, vb]

    def endpoints(self, t: float):
        return _at(self.a, t)[0], _at(self.b, t)[0]


def _pair_kernels() -> dict[str, ca.Function]:
    """Self-contact of particles i and j, ``(d = x_j - x_i, dv = v_j - v_i, gains) -> f_i``."""
    d, dv, gains = ca.SX.sym("d", 3), ca.SX.sym("dv", 3), ca.SX.sym("gains", 4)
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    # i is pushed along -d/r, away from j; the velocity of i relative to j is -dv
    return interaction_kernels("self_contact", d, dv, [gains],
                               *penalty_law(r, -d / r, -dv, gains, d))


class SelfContact:
    """Repulsion between cloth particles nearer than ``contact.thickness`` and not joined by
    a spring; ``excluded`` is the (P, 2) array of joined pairs."""

    kernels = _pair_kernels()

    def __init__(self, contact: Contact, excluded: np.ndarray, n: int):
        self.contact = contact
        e = np.sort(np.asarray(excluded, dtype=np.int64), axis=1)
        self._excluded = np.unique(e[:, 0] * n + e[:, 1])
        self._n = n

    def pairs(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays ``(i, j)``, i < j, of unjoined particles within the thickness."""
        found = cKDTree(x).query_pairs(self.contact.thickness, output_type="ndarray")
        if found.size == 0:
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        found = np.sort(found, axis=1)
        keep = ~np.isin(found[:, 0].astype(np.int64) * self._n + found[:, 1], self._excluded)
        return found[keep, 0].astype(np.intp), found[keep, 1].astype(np.intp)

    def inputs(self, x, v, i, j) -> list[np.ndarray]:
        """The kernels' inputs for the pairs ``(i, j)``: differences and contact gains."""
        gains = np.broadcast_to(self.contact.gains, (i.size, 4))
        return [pair_difference(x, i, j), pair_difference(v, i, j), gains]

    def all_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every unjoined pair (for the symbolic, small-system route)."""
        i, j = np.triu_indices(self._n, 1)
        keep = ~np.isin(i.astype(np.int64) * self._n + j, self._excluded)
        return i[keep], j[keep]
