r"""Analytic bodies a cloth collides with: :class:`Plane`, :class:`Sphere`, :class:`Capsule`
(a segment swept by a sphere), and :class:`Contact`, the parameters of touching one.

A body is geometry only: its signed distance ``phi`` (negative inside), outward unit normal
and surface velocity at a point, as CasADi expressions (:meth:`Body.surface`) of the point
and the body's geometry at time t (:meth:`Body.geometry`).  Any point given may be a function
of time ``t -> (3,)`` so the body moves along a path; its velocity is the central difference
of that path.  How contact acts is an interaction family's job: the paper's stiff repulsive
springs are :class:`~.penalty.BodyPenalty`.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..kernels import MappedKernel


@dataclass(frozen=True)
class Contact:
    """How a body (or the cloth itself) is touched: ``stiffness`` N/m, ``damping`` N s/m,
    ``thickness`` m (the gap kept to the surface) and ``width`` m (the penetration over which
    the penalty stiffness ramps up, see :func:`~.penalty.penalty_law`)."""

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

    ``kind`` names the shape; ``GEOMETRY`` names the geometry inputs and their sizes, in the
    order of :meth:`geometry`; ``contact`` is how the body is touched (:class:`Contact`).
    """

    kind = "body"
    GEOMETRY: dict = {}

    def __init__(self, contact: Contact | None):
        self.contact = Contact() if contact is None else contact

    @staticmethod
    def surface(x, **geometry):
        """``(phi, normal, v_body)`` at the point x as CasADi expressions of x and the
        geometry symbols named in :attr:`GEOMETRY`."""
        raise NotImplementedError

    def geometry(self, t: float) -> list[np.ndarray]:
        """The geometry inputs at time t (positions, sizes, velocities), in GEOMETRY's order."""
        raise NotImplementedError

    def parameters(self, t: float) -> np.ndarray:
        """This body's geometry at time t as one flat vector (the symbolic S)."""
        return np.concatenate([np.ravel(g) for g in self.geometry(t)])


def _plane_surface(x, point, normal, velocity):
    unit = normal / ca.norm_2(normal)
    return ca.dot(x - point, unit), unit, velocity


class Plane(Body):
    """The half-space above a plane through ``point`` with upward ``normal`` (e.g. the ground)."""

    kind = "plane"
    GEOMETRY = {"point": 3, "normal": 3, "velocity": 3}
    surface = staticmethod(_plane_surface)

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


def _sphere_surface(x, center, radius, velocity):
    d = x - center
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    return r - radius, d / r, velocity


class Sphere(Body):
    """A ball of ``radius`` about ``center`` (fixed, or a function of time)."""

    kind = "sphere"
    GEOMETRY = {"center": 3, "radius": 1, "velocity": 3}
    surface = staticmethod(_sphere_surface)

    def __init__(self, center, radius: float, contact=None):
        super().__init__(contact)
        self.center = _point(center, "Sphere center")
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"Sphere radius must be positive, got {radius}")
        self.radius = float(radius)

    def geometry(self, t):
        c, vc = _at(self.center, t)
        return [c, np.array([self.radius]), vc]


def _capsule_surface(x, a, b, radius, va, vb):
    ab = b - a
    s = ca.fmin(ca.fmax(ca.dot(x - a, ab) / (ca.dot(ab, ab) + 1e-12), 0), 1)
    d = x - (a + s * ab)
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    return r - radius, d / r, (1 - s) * va + s * vb


class Capsule(Body):
    """The points within ``radius`` of segment ``a``-``b`` (ends fixed or functions of time)."""

    kind = "capsule"
    GEOMETRY = {"a": 3, "b": 3, "radius": 1, "va": 3, "vb": 3}
    surface = staticmethod(_capsule_surface)

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


@functools.lru_cache(maxsize=None)
def _distance_kernel(body_type: type) -> MappedKernel:
    x = ca.SX.sym("x", 3)
    geo = {key: ca.SX.sym(key, size) for key, size in body_type.GEOMETRY.items()}
    phi = body_type.surface(x, **geo)[0]
    return MappedKernel(ca.Function(f"{body_type.kind}_distance", [x, *geo.values()], [phi]))


def signed_distances(body: Body, x: np.ndarray, t: float) -> np.ndarray:
    """Every point's signed distance to ``body``'s surface at time t (negative inside), for
    ``x`` of shape ``(n, 3)``: the one measure of how deep a particle is in a body."""
    columns = [np.broadcast_to(g, (len(x), np.size(g))) for g in body.geometry(t)]
    return _distance_kernel(type(body))(np.asarray(x, float), *columns)[0].ravel()
