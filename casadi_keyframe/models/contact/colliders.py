r"""Bodies a cloth collides with: :class:`Plane`, :class:`Sphere`, :class:`Capsule` (a segment
swept by a sphere), triangle meshes (:class:`MeshBody`, still or per-frame), and
:class:`Contact`, the parameters of touching one.

A body is geometry only: its signed distance ``phi`` (negative inside), outward unit normal
and surface velocity at a point, as CasADi expressions (:meth:`Body.surface`) of the point
and the body's geometry at time t (:meth:`Body.geometry`).  A body moves in two ways, which
combine: any point given may be a function of time ``t -> (3,)`` (a path), and ``motion``,
a function ``t -> (R, p)``, carries the body's own coordinates to the world's
(``world = R local + p``), so it turns as well.  Velocities are central differences of the
paths and of the motion; the surface velocity at a point includes the rotation
(``v + omega x (x - c)``).  How contact acts is an interaction family's job: the paper's
stiff repulsive springs are :class:`~.penalty.BodyPenalty`, the step's hold
:class:`~.hold.BodyHold`.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...geometry import BodyShape, Patch, Round, TriangleMesh
from ...kernels import MappedKernel
from .tangential import TangentialLaw

STEP = 1e-5  # s: the central differences' half step


@dataclass(frozen=True)
class Contact:
    """How a body (or the cloth itself) is touched: ``stiffness`` N/m, ``damping`` N s/m,
    ``thickness`` m (the gap kept to the surface), ``width`` m (the penetration over which
    the penalty stiffness ramps up, see :func:`~.penalty.penalty_law`) and ``friction``, the
    Coulomb coefficient mu (0: frictionless; see :mod:`.friction`) or a tangential law (a
    :class:`~.tangential.TangentialLaw`, e.g. ``Coulomb(mu)``)."""

    stiffness: float = 2000.0
    damping: float = 1.0
    thickness: float = 0.01
    width: float = 0.005
    friction: float | TangentialLaw = 0.0

    def __post_init__(self):
        numbers = ("stiffness", "damping", "thickness", "width")
        numbers += () if isinstance(self.friction, TangentialLaw) else ("friction",)
        for name in numbers:
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


def _motion(motion):
    """``motion`` (None, or ``t -> (R, p)`` with R a rotation), validated at t = 0."""
    if motion is None:
        return None
    if not callable(motion):
        raise ValueError(f"a body's motion must be a function t -> (R, p), got {motion!r}")
    R, p = (np.asarray(a, dtype=float) for a in motion(0.0))
    if (R.shape != (3, 3) or p.shape != (3,) or not np.all(np.isfinite(R))
            or not np.allclose(R @ R.T, np.eye(3), atol=1e-8) or np.linalg.det(R) <= 0):
        raise ValueError("a body's motion(t) must return (R, p): a 3 x 3 rotation and 3 finite "
                         "numbers (world = R local + p)")
    return motion


class Body:
    """A rigid collider; subclasses give the geometry and its signed distance.

    ``kind`` names the shape; ``GEOMETRY`` names the geometry inputs and their sizes, in the
    order of :meth:`geometry`; ``contact`` is how the body is touched (:class:`Contact`);
    ``motion`` (None: still) turns and moves the body (module docstring).
    """

    kind = "body"
    GEOMETRY: dict = {}
    local = False  # True: the geometry differs per point (a mesh: its closest feature)

    def __init__(self, contact: Contact | None, motion=None):
        self.contact = Contact() if contact is None else contact
        self.motion = _motion(motion)

    @staticmethod
    def surface(x, **geometry):
        """``(phi, normal, v_body)`` at the point x as CasADi expressions of x and the
        geometry symbols named in :attr:`GEOMETRY` (v_body: the surface's velocity there)."""
        raise NotImplementedError

    def geometry(self, t: float) -> list[np.ndarray]:
        """The geometry inputs at time t (positions, sizes, velocities), in GEOMETRY's order."""
        raise NotImplementedError

    def parameters(self, t: float) -> np.ndarray:
        """This body's geometry at time t as one flat vector (the symbolic S)."""
        return np.concatenate([np.ravel(g) for g in self.geometry(t)])

    def signed_distances(self, x: np.ndarray, t: float, reach=None) -> np.ndarray:
        """Every point's signed distance to the surface at time t (:func:`signed_distances`;
        ``reach``: as :meth:`local_geometry`'s)."""
        return signed_distances(self, x, t, reach)

    def shape(self, t: float) -> BodyShape:
        """How the body looks at time t, for pictures and exports (a typed shape of
        :mod:`casadi_keyframe.geometry`)."""
        raise NotImplementedError

    def _floats(self, t: float) -> list[np.ndarray]:
        return [np.asarray(g, dtype=float) for g in self.geometry(t)]

    def local_geometry(self, x: np.ndarray, t: float, reach=None) -> list[np.ndarray]:
        """The geometry at time t as one row per point of ``x`` ``(n, 3)``: the same row
        for every point here (a mesh gives each point its closest feature).  ``reach`` (m,
        one or one per point; None: everywhere): beyond it the caller needs no exact row,
        only one whose distance is beyond it too (a mesh spares its query there)."""
        return [np.broadcast_to(g, (len(x), np.size(g))) for g in self.geometry(t)]

    def reach(self, v: np.ndarray, t: float, dt: float):
        """How far from the body (m, one per point of velocities ``v`` ``(n, 3)``) a point
        may act on it within the step from t: two contact thicknesses, its own travel and
        the body's; None where every row is cheap (a body whose geometry is one row)."""
        if not self.local:
            return None
        return (2 * self.contact.thickness + 1e-3 + dt * np.linalg.norm(v, axis=1)
                + self.travel(t, dt))

    def travel(self, t: float, dt: float) -> float:
        """How far (m) any point of the body moves from t to t + dt (a bound)."""
        return 0.0

    def parts(self) -> tuple:
        """The bodies contact acts on one by one: this one (a mesh: each of its pieces)."""
        return (self,)

    @property
    def moves(self) -> bool:
        """Whether the body moves: a motion, or a point given as a path."""
        return self.motion is not None or any(callable(v) for v in vars(self).values())

    def placed(self, point, t: float) -> np.ndarray:
        """A body point (fixed or a path) in the world at time t."""
        p = np.asarray(point(t) if callable(point) else point, dtype=float)
        if self.motion is None:
            return p
        R, c = self.motion(t)
        return np.asarray(R, float) @ p + np.asarray(c, float)

    def turned(self, direction, t: float) -> np.ndarray:
        """A body direction in the world at time t."""
        d = np.asarray(direction, dtype=float)
        return d if self.motion is None else np.asarray(self.motion(t)[0], float) @ d

    def moving(self, point, t: float):
        """``(position, velocity)`` of a body point in the world at time t."""
        p = self.placed(point, t)
        if self.motion is None and not callable(point):
            return p, np.zeros(3)
        return p, (self.placed(point, t + STEP) - self.placed(point, t - STEP)) / (2 * STEP)

    def spin(self, t: float) -> np.ndarray:
        """The angular velocity (rad/s, world) of the body's motion at time t."""
        if self.motion is None:
            return np.zeros(3)
        R0, R1 = (np.asarray(self.motion(t + s)[0], float) for s in (-STEP, STEP))
        W = (R1 - R0) / (2 * STEP) @ np.asarray(self.motion(t)[0], float).T
        return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


def _spun(omega, x, centre):
    return ca.cross(omega, x - centre)


def _plane_surface(x, point, normal, velocity, omega):
    unit = normal / ca.norm_2(normal)
    return ca.dot(x - point, unit), unit, velocity + _spun(omega, x, point)


class Plane(Body):
    """The half-space above a plane through ``point`` with upward ``normal`` (e.g. the ground)."""

    kind = "plane"
    GEOMETRY = {"point": 3, "normal": 3, "velocity": 3, "omega": 3}
    surface = staticmethod(_plane_surface)

    def __init__(self, point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), contact=None, motion=None):
        super().__init__(contact, motion)
        self.point = _point(point, "Plane point")
        self.normal = np.asarray(normal, dtype=float)
        if self.normal.shape != (3,) or not np.isfinite(self.normal).all() or not self.normal.any():
            raise ValueError(f"Plane normal must be 3 finite numbers, not all zero, got {normal!r}"
                             " (a plane turns by its motion)")

    def geometry(self, t):
        p, vp = self.moving(self.point, t)
        return [p, self.turned(self.normal, t), vp, self.spin(t)]

    def shape(self, t):
        point, normal, *_ = self._floats(t)
        return Patch(point, normal)


def _sphere_surface(x, center, radius, velocity, omega):
    d = x - center
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    return r - radius, d / r, velocity + _spun(omega, x, center)


class Sphere(Body):
    """A ball of ``radius`` about ``center`` (fixed, or a function of time)."""

    kind = "sphere"
    GEOMETRY = {"center": 3, "radius": 1, "velocity": 3, "omega": 3}
    surface = staticmethod(_sphere_surface)

    def __init__(self, center, radius: float, contact=None, motion=None):
        super().__init__(contact, motion)
        self.center = _point(center, "Sphere center")
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"Sphere radius must be positive, got {radius}")
        self.radius = float(radius)

    def geometry(self, t):
        c, vc = self.moving(self.center, t)
        return [c, np.array([self.radius]), vc, self.spin(t)]

    def shape(self, t):
        center, radius, *_ = self._floats(t)
        return Round(center, center, float(radius[0]))


def _capsule_surface(x, a, b, radius, va, vb, omega):
    ab = b - a
    s = ca.fmin(ca.fmax(ca.dot(x - a, ab) / (ca.dot(ab, ab) + 1e-12), 0), 1)
    axis = a + s * ab
    d = x - axis
    r = ca.sqrt(ca.dot(d, d) + 1e-12)
    return r - radius, d / r, (1 - s) * va + s * vb + _spun(omega, x, axis)


class Capsule(Body):
    """The points within ``radius`` of segment ``a``-``b`` (ends fixed or functions of time).

    Its spin is the ends' (``ab x (vb - va) / |ab|^2``) plus its motion's about the axis."""

    kind = "capsule"
    GEOMETRY = {"a": 3, "b": 3, "radius": 1, "va": 3, "vb": 3, "omega": 3}
    surface = staticmethod(_capsule_surface)

    def __init__(self, a, b, radius: float, contact=None, motion=None):
        super().__init__(contact, motion)
        self.a, self.b = _point(a, "Capsule end a"), _point(b, "Capsule end b")
        if not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"Capsule radius must be positive, got {radius}")
        self.radius = float(radius)

    def geometry(self, t):
        (a, va), (b, vb) = self.moving(self.a, t), self.moving(self.b, t)
        ab = b - a
        length2 = max(float(ab @ ab), 1e-12)
        roll = ab * (self.spin(t) @ ab) / length2
        return [a, b, np.array([self.radius]), va, vb, np.cross(ab, vb - va) / length2 + roll]

    def shape(self, t):
        a, b, radius, *_ = self._floats(t)
        return Round(a, b, float(radius[0]))

    def endpoints(self, t: float):
        return self.placed(self.a, t), self.placed(self.b, t)


def _feature_surface(x, point, edge, normal, flat, side, velocity, spread):
    r = x - point
    d = r - edge * ca.dot(edge, r)  # from the feature's line (an edge) or point (a vertex)
    size = ca.sqrt(ca.dot(d, d) + flat)  # exact off a plane (the normal is a unit vector)
    phi = flat * ca.dot(normal, r) + (1 - flat) * side * size
    n = flat * normal + (1 - flat) * side * d / size
    return phi, n, velocity + ca.mtimes(ca.reshape(spread, 3, 3).T, r)


class MeshBody(Body):
    """A triangle mesh: ``vertices`` ``(v, 3)`` and ``faces`` ``(f, 3)``, still, or moving
    through ``frames`` ``(k, v, 3)`` at ``times`` ``(k,)`` s (or ``fps``; linear between
    frames, held before the first and after the last), in the body's own coordinates, which
    ``motion`` places.  A mesh of several pieces is their union.

    Each point's geometry is its closest feature (:mod:`~...meshes.distance`, libigl):
    ``point`` its closest point, ``flat`` 1 on a face (``normal`` the face's), 0 on an edge
    (``edge`` its direction) or a vertex, ``side`` the sign, and the surface's velocity
    there, ``velocity`` and its ``spread`` over the feature (3 x 3).  Within the feature the
    distance is smooth and differentiated; the feature is the point's choice, so across a
    switch the distance and normal are continuous and the normal's derivative is that of
    the feature chosen.  :meth:`geometry` gives the vertices in the world and the faces.
    """

    kind = "mesh"
    GEOMETRY = {"point": 3, "edge": 3, "normal": 3, "flat": 1, "side": 1, "velocity": 3,
                "spread": 9}
    local = True
    surface = staticmethod(_feature_surface)
    KEPT = 8  # shapes and queries remembered (a step asks at t and t + dt, several times)

    def __init__(self, vertices, faces, frames=None, *, fps: float | None = None, times=None,
                 contact=None, motion=None, source=None):
        super().__init__(contact, motion)
        from ...meshes.distance import pieces, require_igl
        require_igl()
        self.vertices, self.faces = _checked_mesh(vertices, faces)
        self.frames, self.times = _checked_frames(frames, fps, times, len(self.vertices))
        self.pieces = pieces(self.faces, len(self.vertices))
        self.source = source
        self._shapes, self._rows = {}, {}

    @classmethod
    def from_file(cls, path, *, rest=None, fps: float | None = None, contact=None,
                  motion=None) -> "MeshBody":
        """The body in a mesh file: OBJ, PLY, USD (still or time-sampled), or a PC2 cache
        with its rest OBJ (``rest``, default ``NAME_rest.obj``) at ``fps`` frames per second
        (:func:`~...meshes.read_animated`)."""
        from ...meshes import read_animated
        found = read_animated(path, rest=rest, fps=fps)
        return cls(found.mesh.vertices, found.mesh.faces, found.frames, times=found.times,
                   contact=contact, motion=motion, source=path)

    def parts(self) -> tuple:
        """Each piece as a body of its own (the hold chooses among them per particle, and a
        step that ends inside another piece is revised on that piece), or this one."""
        if len(self.pieces) == 1:
            return (self,)
        out = []
        for piece in self.pieces:
            used, faces = np.unique(self.faces[piece], return_inverse=True)
            out.append(MeshBody(self.vertices[used], faces.reshape(-1, 3),
                                None if self.frames is None else self.frames[:, used],
                                times=self.times, contact=self.contact, motion=self.motion,
                                source=self.source))
        return tuple(out)

    def __getstate__(self):  # the trees are rebuilt where the body is unpickled
        return {**vars(self), "_shapes": {}, "_rows": {}}

    @property
    def moves(self) -> bool:
        return self.motion is not None or self.frames is not None

    def _local_vertices(self, t: float) -> np.ndarray:
        if self.frames is None:
            return self.vertices
        s = np.interp(t, self.times, np.arange(len(self.times)))
        k = min(int(s), len(self.times) - 2)
        return self.frames[k] + (s - k) * (self.frames[k + 1] - self.frames[k])

    def _shape(self, t: float):
        from ...meshes.distance import MeshShape
        key = None if self.frames is None else float(t)
        if key not in self._shapes:
            _forget(self._shapes, self.KEPT)
            self._shapes[key] = MeshShape(self._local_vertices(t), self.faces, self.pieces)
        return self._shapes[key]

    def _placement(self, t: float):
        if self.motion is None:
            return np.eye(3), np.zeros(3)
        R, p = self.motion(t)
        return np.asarray(R, float), np.asarray(p, float)

    def travel(self, t, dt):
        if not self.moves:
            return 0.0
        return float(np.linalg.norm(self.world_vertices(t + dt) - self.world_vertices(t),
                                    axis=1).max())

    def world_vertices(self, t: float) -> np.ndarray:
        """The vertices in the world at time t."""
        R, p = self._placement(t)
        return self._local_vertices(t) @ R.T + p

    def geometry(self, t):
        return [self.world_vertices(t), self.faces]

    def shape(self, t):
        return TriangleMesh(*self.geometry(t))

    def parameters(self, t):
        return np.zeros(0)  # per point: local_geometry

    def local_geometry(self, x, t, reach=None):
        """Each point's closest feature (class docstring), kept for the same points and
        time (a still body's for any time: a step's queries at t and t + dt, and the next
        step's at its start, are one), exact within ``reach`` (:meth:`Body.local_geometry`)
        and wherever an earlier query asked."""
        x = np.ascontiguousarray(x, dtype=float)
        key = (float(t) if self.moves else None, x.shape, x.tobytes())
        if key not in self._rows:
            _forget(self._rows, self.KEPT)
            R, p = self._placement(t)
            self._rows[key] = [None, np.zeros(len(x), bool), self._shape(t).bounds((x - p) @ R)]
        entry = self._rows[key]
        rows, exact, bounds = entry
        missing = ~exact if reach is None else (bounds[0] <= reach) & ~exact
        if rows is None or missing.any():
            found = self._features(x, float(t), missing, bounds)
            if rows is not None:  # what was exact stays as it was
                found = [np.where(exact[:, None], a, b) for a, b in zip(rows, found)]
            entry[:2] = found, missing | exact
        return entry[0]

    def _features(self, x, t, near=None, bounds=None):
        R, p = self._placement(t)
        found = self._shape(t).closest((x - p) @ R, near, bounds)
        if self.moves:
            ahead, behind = self.world_vertices(t + STEP), self.world_vertices(t - STEP)
            corner = ((ahead - behind) / (2 * STEP))[found.corners]  # (k, 3, 3)
        else:
            corner = np.zeros(found.corners.shape + (3,))
        velocity = np.einsum("ki,kia->ka", found.weights, corner)
        spread = np.einsum("kia,kib->kab", corner, found.gradients @ R.T)
        return [found.point @ R.T + p, found.edge @ R.T, found.normal @ R.T,
                found.flat[:, None].astype(float), found.side[:, None], velocity,
                spread.reshape(len(x), 9)]


def _forget(cache: dict, kept: int) -> None:
    while len(cache) >= kept:
        cache.pop(next(iter(cache)))


def _checked_mesh(vertices, faces):
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3 or not np.isfinite(v).all():
        raise ValueError(f"MeshBody vertices must be (v, 3) finite numbers, v >= 3, got an "
                         f"array of shape {v.shape}")
    if (f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or f.dtype.kind not in "iu"
            or f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"MeshBody faces must be (f, 3) vertex indices in 0..{len(v) - 1}, "
                         f"got an array of shape {f.shape}")
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    if (area <= 1e-12 * area.max()).any():
        raise ValueError(f"MeshBody: {int((area <= 1e-12 * area.max()).sum())} face(s) have "
                         "no area; remove them (Blender: Mesh > Clean Up > Degenerate "
                         "Dissolve)")
    return v, f.astype(np.int64)


def _checked_frames(frames, fps, times, count):
    """``(frames (k, v, 3), times (k,))`` validated, or ``(None, None)`` for a still mesh."""
    if frames is None:
        return None, None
    frames = np.asarray(frames, dtype=float)
    if frames.ndim != 3 or frames.shape[1:] != (count, 3) or not np.isfinite(frames).all():
        raise ValueError(f"MeshBody frames must be (k, {count}, 3) finite vertices, got an "
                         f"array of shape {frames.shape}")
    if times is None:
        if fps is None or not fps > 0:
            raise ValueError("MeshBody frames need their times: give fps (frames per second) "
                             "or times (s)")
        times = np.arange(len(frames)) / float(fps)
    times = np.asarray(times, dtype=float)
    if times.shape != (len(frames),) or len(frames) < 2 or (np.diff(times) <= 0).any():
        raise ValueError(f"MeshBody frames need at least 2 frames at increasing times, one "
                         f"time per frame; got {len(frames)} frames, times {times.shape}")
    return frames, times


@functools.lru_cache(maxsize=None)
def _distance_kernel(body_type: type) -> MappedKernel:
    x = ca.SX.sym("x", 3)
    geo = {key: ca.SX.sym(key, size) for key, size in body_type.GEOMETRY.items()}
    phi = body_type.surface(x, **geo)[0]
    return MappedKernel(ca.Function(f"{body_type.kind}_distance", [x, *geo.values()], [phi]))


def signed_distances(body: Body, x: np.ndarray, t: float, reach=None) -> np.ndarray:
    """Every point's signed distance to ``body``'s surface at time t (negative inside), for
    ``x`` of shape ``(n, 3)``: the one measure of how deep a particle is in a body; with
    ``reach``, exact within it and beyond it beyond (:meth:`Body.local_geometry`)."""
    x = np.asarray(x, float)
    return _distance_kernel(type(body))(x, *body.local_geometry(x, t, reach))[0].ravel()
