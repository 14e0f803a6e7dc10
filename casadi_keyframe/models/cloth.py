r"""Mass-spring cloth in 3-D: a list of interaction families (:mod:`.families` sums them).

A cloth's families are, in this order: its springs (:class:`~.springs.ChoiKoSprings`),
gravity and air drag (:class:`~.gravity_drag.GravityAndDrag`), how it touches its bodies
(``collision``, :mod:`.contact.collisions`: the paper's penalty springs, the step's hold, or both),
self-contact (:class:`~.contact.penalty.SelfPenalty`) and any further ``families`` given (a
dihedral bending, :mod:`.bending`).  :class:`ClothModel` builds them from a grid or a mesh
and owns its constraints (:mod:`.constraints`: pinned and attached particles) and its
reports (stretch, penetration).  A new force law is one family file, given to a cloth as
one list entry.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..state import SimulationError
from .base import Model, PhysicalReport, Surface
from .contact.colliders import Body, Contact, signed_distances
from .contact.collisions import DEFAULT_COLLISION, check_collision, collision_families
from .constraints import Constraints
from .families import FamilyModel, check_families
from .gravity_drag import GravityAndDrag
from .contact.penalty import SelfPenalty
from .springs import ChoiKoSprings, Springs
from .topology import grid_topology, lumped_masses, mesh_topology

PLANES = ("xz", "xy")


@dataclass(frozen=True)
class ClothParams:
    """Cloth material, SI units; defaults suit a ~1 m, ~0.3 kg sheet at dt = 1/60..1/30 s.

    ``stretch``, ``shear``: linear tension stiffness per spring, N/m (on a square grid the
    sheet's membrane stiffness does not depend on the resolution).  ``bend``: buckling
    stiffness ``k_b``, N m^2.  ``damping``: along-spring damping c, N s/m.  ``air_drag``:
    drag per unit mass, 1/s.  ``gravity``: m/s^2.  ``eps``: length regularisation, m.
    ``blowup_stretch``: a spring this many times its rest length means a step has failed.
    ``rest_band``: the strain band below rest over which the linearized step's spring
    stiffness turns smoothly from the buckling slope to the tension stiffness
    (:func:`~.springs.rest_lack`; the force law is unchanged); 0, the paper's step.
    """

    stretch: float = 500.0
    shear: float = 50.0
    bend: float = 2e-5
    damping: float = 0.02
    air_drag: float = 0.1
    gravity: tuple = (0.0, 0.0, -9.81)
    eps: float = 1e-6
    blowup_stretch: float = 5.0
    rest_band: float = 0.0

    def __post_init__(self):
        for name in ("stretch", "shear", "bend", "damping", "air_drag"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"ClothParams.{name} must be non-negative and finite, got {value}")
        if not self.eps > 0:
            raise ValueError(f"ClothParams.eps must be positive, got {self.eps}")
        if not 0 <= self.rest_band < 1:
            raise ValueError(f"ClothParams.rest_band must be in [0, 1), got {self.rest_band}")
        if not self.blowup_stretch > 1:
            raise ValueError(f"ClothParams.blowup_stretch must be > 1, got {self.blowup_stretch}")
        g = tuple(float(c) for c in self.gravity)
        if len(g) != 3 or not np.all(np.isfinite(g)):
            raise ValueError(f"ClothParams.gravity must be 3 finite numbers, got {self.gravity}")
        object.__setattr__(self, "gravity", g)


def _frozen(*arrays):
    for a in arrays:
        a.flags.writeable = False


class ClothModel(FamilyModel, Model, PhysicalReport, Surface):
    """An immutable cloth of n particles with fixed springs; build with :meth:`grid` or
    :meth:`from_mesh`.  States are ``(n, 3)`` arrays; the flat 3n ordering is ``x.ravel()``.

    ``colliders``: bodies the cloth touches (``collision``, :mod:`.contact.collisions`): by default
    the paper's stiff springs in the contact layer with the step holding every particle on
    the body's surface, so none passes through (``"guarded"``); the hold on the layer's
    surface with no spring (``"constraint"``); or the springs alone (``"penalty"``, the
    paper's); ``self_contact``: the :class:`~.contact.colliders.Contact` of cloth with itself
    (penalty; None: none); ``attachments``: particles led along paths; ``families``:
    further interaction families, summed after the others.
    """

    dim = 3

    def __init__(self, rest_positions, faces, masses, springs: Springs,
                 params: ClothParams | None = None, pinned=(), jit: bool | None = None,
                 colliders=(), self_contact: Contact | None = None, attachments=(),
                 families=(), collision: str = DEFAULT_COLLISION):
        params = ClothParams() if params is None else params
        masses = np.asarray(masses, dtype=float)
        if masses.shape != (len(rest_positions),) or np.any(masses <= 0):
            raise ValueError("masses must be positive, one per particle; build the cloth with "
                             "ClothModel.grid or ClothModel.from_mesh")
        n = masses.size
        colliders = tuple(colliders)
        for body in colliders:
            if not isinstance(body, Body):
                raise ValueError(f"colliders must be Plane, Sphere or Capsule bodies, got {body!r}")
        check_collision(collision)
        set_ = functools.partial(object.__setattr__, self)
        set_("rest_positions", np.array(rest_positions, dtype=float))
        set_("faces", np.array(faces))
        set_("masses", masses.copy())
        _frozen(self.rest_positions, self.faces, self.masses)
        set_("springs", springs)
        set_("params", params)
        set_("jit", jit)
        set_("colliders", colliders)
        set_("self_contact", self_contact)
        set_("collision", collision)
        set_("constraints", Constraints(n, pinned, attachments))
        set_("pinned", self.constraints.pinned)
        set_("attachments", self.constraints.attachments)
        spring_family = ChoiKoSprings(springs, n, stiffness=(params.stretch, params.shear,
                                                             params.bend),
                                      damping=params.damping, eps=params.eps,
                                      rest_band=params.rest_band, jit=jit)
        self_family = (() if self_contact is None else
                       (SelfPenalty(self_contact, np.stack([springs.i, springs.j], 1), n, jit),))
        set_("families", check_families((
            spring_family, GravityAndDrag(self.masses, params.gravity, params.air_drag),
            *collision_families(collision, colliders, n, jit, self.masses, params.gravity),
            *self_family, *families)))

    def __setattr__(self, name, value):
        raise AttributeError(f"a ClothModel is immutable: build a new one instead of setting "
                             f"{name!r}")

    # -- construction --------------------------------------------------------------------
    @classmethod
    def grid(cls, rows: int, cols: int, *, width: float = 1.0, height: float = 1.0,
             mass: float = 1.0, params: ClothParams | None = None, pinned=(),
             origin=(0.0, 0.0, 0.0), plane: str = "xz", jit: bool | None = None,
             **scene):
        """A rows x cols sheet; particle ``k = r * cols + c`` starts at ``origin`` plus

        * plane "xz" (hanging, z up): ``(c width/(cols-1), 0, -r height/(rows-1))``, so
          row 0 is the top edge;
        * plane "xy" (lying flat):    ``(c width/(cols-1), r height/(rows-1), 0)``.

        ``mass`` is the total mass in kg, lumped by area (corners 1/4 of inner particles).
        ``scene`` takes ``colliders``, ``collision``, ``self_contact``, ``attachments`` and
        ``families`` (see the class).
        """
        if int(rows) != rows or int(cols) != cols or rows < 2 or cols < 2:
            raise ValueError(f"a cloth grid needs rows >= 2 and cols >= 2, got {rows} x {cols}")
        if not (width > 0 and height > 0):
            raise ValueError(f"grid width and height must be positive, got {width}, {height}")
        if plane not in PLANES:
            raise ValueError(f"plane must be one of {PLANES}, got {plane!r}")
        rows, cols = int(rows), int(cols)
        r, c = np.divmod(np.arange(rows * cols), cols)
        a, b = c * width / (cols - 1), r * height / (rows - 1)
        zero = np.zeros_like(a)
        local = np.stack([a, zero, -b] if plane == "xz" else [a, b, zero], axis=1)
        vertices = _check_vector(origin, "origin") + local
        pairs, quads = grid_topology(rows, cols)
        masses = _total_mass(mass) and lumped_masses(vertices, quads, mass)
        faces = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])  # split along a-e
        return cls._build(vertices, faces, pairs, masses, params, pinned, jit, scene)

    @classmethod
    def from_mesh(cls, vertices, faces, *, mass: float = 1.0, params: ClothParams | None = None,
                  pinned=(), jit: bool | None = None, **scene):
        """A cloth from a triangle mesh: ``vertices`` (n, 3) in m, ``faces`` (m, 3) ints.

        Stretch springs on the edges, bend springs between the two vertices opposite each
        interior edge, no shear springs; ``mass`` (kg, total) is lumped by triangle area.
        """
        v = np.asarray(vertices, dtype=float)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 2 or not np.all(np.isfinite(v)):
            raise ValueError(f"vertices must be a finite (n, 3) array with n >= 2, got {v.shape}")
        f = np.asarray(faces)
        if (f.ndim != 2 or f.shape[1] != 3 or len(f) < 1
                or not np.issubdtype(f.dtype, np.integer)):
            raise ValueError(
                f"faces must be a non-empty (m, 3) integer array, got {f.shape} {f.dtype}")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"faces index vertices 0..{len(v) - 1}, found {f.min()}..{f.max()}")
        if np.any((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])):
            raise ValueError("a face repeats a vertex; every triangle needs 3 distinct vertices")
        f = f.astype(np.intp)
        masses = _total_mass(mass) and lumped_masses(v, f, mass)
        return cls._build(v, f, mesh_topology(f), masses, params, pinned, jit, scene)

    @classmethod
    def from_file(cls, path, *, pinned=(), mass: float = 1.0, params: ClothParams | None = None,
                  jit: bool | None = None, **scene):
        """A cloth from a mesh file (OBJ, PLY or USD, or a :class:`~..meshes.Mesh` already
        read), its vertices the particles in the file's order (see :mod:`..meshes`, which
        reads and checks it); ``pinned``: vertex indices, the name of one of the file's
        vertex sets, or a :class:`~..meshes.PinBox`; the rest as :meth:`from_mesh`."""
        from ..meshes import Mesh, pin_indices, read_mesh

        mesh = path if isinstance(path, Mesh) else read_mesh(path)
        return cls.from_mesh(mesh.vertices, mesh.faces, mass=mass, params=params,
                             pinned=pin_indices(mesh, pinned), jit=jit, **scene)

    @classmethod
    def _build(cls, vertices, faces, pairs, masses, params, pinned, jit, scene):
        params = ClothParams() if params is None else params
        kinds = sorted(pairs)
        ij = np.vstack([pairs[k] for k in kinds]).astype(np.intp)
        kind = np.concatenate([np.full(len(pairs[k]), k) for k in kinds])
        d = vertices[ij[:, 1]] - vertices[ij[:, 0]]
        rest = np.sqrt(np.einsum("pk,pk->p", d, d) + params.eps ** 2)  # regularised: f(rest)=0
        springs = Springs(ij[:, 0].copy(), ij[:, 1].copy(), rest, kind)
        _frozen(springs.i, springs.j, springs.rest, springs.kind)
        options = {"colliders", "self_contact", "attachments", "families", "collision"}
        unknown = set(scene) - options
        if unknown:
            raise TypeError(f"unknown cloth option(s) {sorted(unknown)}; scene options are "
                            f"{', '.join(sorted(options))}")
        return cls(vertices, faces, masses, springs, params, pinned, jit, **scene)

    @property
    def n(self) -> int:
        return len(self.masses)

    # -- constraints and reports ---------------------------------------------------------
    def free_mask(self) -> np.ndarray:
        """Boolean mask over the 3n velocity components: False for pinned and attached ones."""
        return self.constraints.free

    def prescribed_velocity(self, x: np.ndarray, t: float, dt: float) -> np.ndarray:
        return self.constraints.prescribed_velocity(x, t, dt)

    def constraint_targets(self, t: float) -> np.ndarray:
        return self.constraints.targets(t)

    def prescribed_velocity_symbolic(self, X, targets, dt):
        return self.constraints.prescribed_velocity_symbolic(X, targets, dt)

    def max_stretch(self, x: np.ndarray) -> float:
        """The largest spring length over rest length (1 at rest); a blow-up shows here first."""
        return float(self.springs.stretch(x).max())

    def check_state(self, x: np.ndarray, v: np.ndarray, step: int) -> None:
        """Non-finite or unbounded states and springs past ``params.blowup_stretch`` times
        their rest length raise :class:`SimulationError`."""
        super().check_state(x, v, step)
        stretch = self.max_stretch(x)
        if stretch > self.params.blowup_stretch:
            raise SimulationError(
                f"cloth blew up at step {step}: a spring is {stretch:.3g} times its rest "
                "length; reduce dt, the contact stiffness or the speed of moving colliders, "
                "or bound the controls", step)

    def penetration(self, x: np.ndarray, t: float = 0.0) -> float:
        """How deep (m) the deepest particle is inside a collider's surface at time t (0 if
        none is): the library's one measure of penetration."""
        deepest = 0.0
        for body in self.colliders:
            deepest = max(deepest, float(-signed_distances(body, x, t).min()))
        return deepest

    def physical_report(self, x: np.ndarray, dt: float) -> dict:
        """Whether the frames ``x`` (``(frames, n, 3)``, ``dt`` apart) stay physical: the
        largest spring stretch (length over rest length) and, if it has colliders, the
        deepest particle inside one (m), each with the frame where it happens."""
        stretch = [self.max_stretch(frame) for frame in x]
        out = {"max_stretch": max(stretch), "max_stretch_frame": int(np.argmax(stretch))}
        if self.colliders:
            depth = [self.penetration(frame, k * dt) for k, frame in enumerate(x)]
            out.update(max_penetration=max(depth), max_penetration_frame=int(np.argmax(depth)))
        return out


def _total_mass(mass) -> bool:
    if not (np.isscalar(mass) and np.isfinite(mass) and mass > 0):
        raise ValueError(f"the cloth's total mass must be a positive finite number, got {mass}")
    return True


def _check_vector(value, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value}")
    return a
