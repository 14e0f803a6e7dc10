r"""Mass-spring cloth with the Choi-Ko (2002) buckling response, in 3-D.

For a spring (i, j) of rest length ``L`` let ``d = x_j - x_i``, ``dv = v_j - v_i``, the
regularised length ``r = sqrt(|d|^2 + eps^2)`` and ``u = d / r``.  The force on particle i is

* tension, ``r >= L``:      ``f_i = k_t (r - L) u``                 (pulls i toward j)
* compression, ``r < L``:   ``f_i = -k_b kappa^2 u``               (pushes the ends apart)
* damping, always:          ``f_i += c ((dv . u) u)``

and j feels ``-f_i``, so internal forces sum to zero.  Under compression the spring is
assumed to buckle into a circular arc of length L with chord r, so its curvature solves
``r / L = sinc(kappa L / 2)`` (``sinc(y) = sin(y) / y``), i.e. ``kappa^2 = 4 y^2 / L^2``
with ``y = sinc^{-1}(s)``, ``s = r / L``.  ``z = y^2`` is analytic in ``w = 1 - s`` on
[0, 1] (``z ~ 6 w`` near rest), so it is fitted once as ``z(w) = w P(w)`` with P a
degree-10 polynomial (:data:`SINC_INV_COEFFS`, |y error| < 1e-5): the force vanishes at
``r = L`` exactly and no square root appears in the kernel.

No strut-like resistance before buckling.  The law's radial stiffness jumps at ``r = L``
from ``k_t`` to the buckling slope ``24 k_b / L^3``, so the linearized step's matrix jumps
when a spring passes its rest length (the objective is only piecewise smooth there).  A
compressive force that resisted like a strut instead (stiffness ``k_t`` over a few percent of
strain, as an earlier version of this model did to make the stiffness continuous) gives every
compressed spring a transverse stiffness ``m / r < 0`` large enough to make a flat,
compressed sheet (a sheet hanging in its plane) a buckling saddle: the passive sheet stays
exactly planar, and the gradient of any keyframe objective grows by orders of magnitude per
second of simulated time along it
(``tests/test_cloth_model.py::test_flat_hanging_sheet_has_a_meaningful_gradient``).  Blending
only the step's stiffness (continuous matrix, Choi-Ko force) keeps the gradient meaningful
but breaks the step's agreement with full backward Euler and solved fig. 4 worse; real cloth
buckles at a tiny load, which is what the Choi-Ko law says.

Spring kinds and their stiffnesses (:class:`ClothParams`):

* stretch (grid neighbours / mesh edges):  ``k_t = stretch``, ``k_b = bend``
* shear   (both diagonals of a grid quad): ``k_t = shear``,   ``k_b = bend``
* bend    (skip one particle / across an interior edge): ``k_b = bend`` and
  ``k_t = 24 bend / L^3``, the slope of the buckling force at ``r = L``, so a bend spring's
  force is C^1 across its rest length.

Each particle also feels gravity ``m_i g`` and linear air drag ``-air_drag m_i v_i`` (mass
proportional, so the drag acceleration does not depend on the resolution), plus the contact
forces of the model's colliders and self-contact (:mod:`.colliders`).  Pinned particles and
:class:`Attachment` s (particles led along a path: a hand, a shoulder) are recorded here;
the integrator imposes their velocities.

The spring law is one SX kernel ``(d, dv, L, k_t, k_b, c) -> f_i`` and its Jacobian kernel
``-> (K, D)`` (row-major 3x3): ``D = df_i/d dv`` and K the stiffness ``df_i/dd`` without the
transverse term of compressed springs (:func:`spring_law`).  Since ``d = x_j - x_i`` the spring
adds ``-K`` to blocks (i, i), (j, j) and ``+K`` to (i, j), (j, i) of df/dx (D likewise for
df/dv); drag and the bodies' contacts add per-particle diagonal blocks.  The sparse pattern
and the COO -> CSC map are built once, so a Jacobian call fills one data vector with a
precomputed signed sparse gather matrix: O(springs).  Self-contact pairs change every step
and are added as a separate sparse term.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..kernels import (MappedKernel, interaction_kernels, pair_difference, pair_incidence,
                       scatter_pairs)
from .blocks import BlockPattern, Blocks
from .colliders import Body, Contact, SelfContact

KERNELS = ("force", "jac", "df_dx", "vjp", "jvp")  # of every interaction, see interaction_kernels

SPRING_KINDS = ("stretch", "shear", "bend")
STRETCH, SHEAR, BEND = range(3)
PLANES = ("xz", "xy")
# a spring within this relative distance of its rest length counts as at rest (tension
# branch): the law's kink there must not be decided by round-off, which differs between the
# numeric and symbolic routes for states at rest up to it (a sheet at rest, or translating)
REST_TOLERANCE = 1e-9


def _fit_sinc_inverse(degree: int = 10) -> np.ndarray:
    """Coefficients of P (highest power first) with ``sinc^{-1}(1 - w)^2 ~= w P(w)``."""
    y = np.pi * (1 - np.cos(np.linspace(0, np.pi, 4001)[1:])) / 2  # dense at both ends
    w = 1 - np.sin(y) / y
    return np.polyfit(w, y ** 2 / w, degree)


SINC_INV_COEFFS = _fit_sinc_inverse()


def sinc_inverse_squared(s):
    """``y^2`` with ``sinc(y) = s`` for s in [0, 1]; numpy arrays or CasADi expressions."""
    w = 1 - s
    acc = 0 * w + SINC_INV_COEFFS[0]
    for c in SINC_INV_COEFFS[1:]:  # Horner
        acc = acc * w + c
    return w * acc


def sinc_inverse(s: np.ndarray) -> np.ndarray:
    """``y`` in [0, pi] with ``sin(y) / y = s``, for s in [0, 1] (numpy)."""
    return np.sqrt(np.maximum(sinc_inverse_squared(np.asarray(s, dtype=float)), 0.0))


@dataclass(frozen=True)
class ClothParams:
    """Cloth material, SI units; defaults suit a ~1 m, ~0.3 kg sheet at dt = 1/60..1/30 s.

    ``stretch``, ``shear``: linear tension stiffness per spring, N/m (on a square grid the
    sheet's membrane stiffness does not depend on the resolution).  ``bend``: buckling
    stiffness ``k_b``, N m^2.  ``damping``: along-spring damping c, N s/m.  ``air_drag``:
    drag per unit mass, 1/s.  ``gravity``: m/s^2.  ``eps``: length regularisation, m.
    """

    stretch: float = 500.0
    shear: float = 50.0
    bend: float = 2e-5
    damping: float = 0.02
    air_drag: float = 0.1
    gravity: tuple = (0.0, 0.0, -9.81)
    eps: float = 1e-6

    def __post_init__(self):
        for name in ("stretch", "shear", "bend", "damping", "air_drag"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"ClothParams.{name} must be non-negative and finite, got {value}")
        if not self.eps > 0:
            raise ValueError(f"ClothParams.eps must be positive, got {self.eps}")
        g = tuple(float(c) for c in self.gravity)
        if len(g) != 3 or not np.all(np.isfinite(g)):
            raise ValueError(f"ClothParams.gravity must be 3 finite numbers, got {self.gravity}")
        object.__setattr__(self, "gravity", g)


def spring_law(d, dv, L, k_t, k_b, c, eps: float):
    """``(f_i, K)`` of one spring as CasADi expressions (see the module docstring): the force
    on particle i and the stiffness ``K ~ df_i/dd`` the implicit step uses.

    With magnitude ``m(r)`` and ``f_i = m u``: ``df_i/dd = m' u u^T + m (I/r - d d^T/r^3)``.
    Under compression ``m < 0`` and the transverse term is negative: it says a compressed
    spring would rather rotate than shorten, and at fine resolution it makes the step matrix
    ``M - dt D - dt^2 K`` indefinite.  As Choi and Ko, K keeps it only under tension
    (``max(m, 0)``); ``m' >= 0`` on both branches, so K is negative semi-definite and the
    step matrix positive definite for every dt.
    """
    r = ca.sqrt(ca.dot(d, d) + eps ** 2)
    u = d / r
    m = ca.if_else(r >= L * (1 - REST_TOLERANCE), k_t * (r - L),
                   -k_b * 4 * sinc_inverse_squared(r / L) / L ** 2)
    force = m * u + c * ca.dot(dv, u) * u
    stiffness = (ca.mtimes(u, ca.jacobian(m, d))
                 + ca.fmax(m, 0) * (ca.SX.eye(3) / r - ca.mtimes(d, d.T) / r ** 3))
    return force, stiffness


def spring_kernels(eps: float) -> dict[str, ca.Function]:
    """``force(d, dv, L, k_t, k_b, c) -> f_i``, ``jac(...) -> (vec K, vec D)`` (row-major) and
    ``vjp`` (see :func:`interaction_kernels`), K from :func:`spring_law`.

    As Baraff and Witkin, the damping force's position derivative (not symmetric) is left
    out of K, so K is symmetric.
    """
    d, dv = ca.SX.sym("d", 3), ca.SX.sym("dv", 3)
    scalars = [ca.SX.sym(name) for name in ("L", "k_t", "k_b", "c")]
    force, stiffness = spring_law(d, dv, *scalars, eps)
    return interaction_kernels("cloth_spring", d, dv, scalars, force, stiffness)


@dataclass(frozen=True)
class Springs:
    """Springs as parallel arrays: endpoints ``i``, ``j``, ``rest`` length (m) and ``kind``
    (index into SPRING_KINDS)."""

    i: np.ndarray
    j: np.ndarray
    rest: np.ndarray
    kind: np.ndarray

    def count(self, kind: str) -> int:
        return int(np.sum(self.kind == SPRING_KINDS.index(kind)))


def grid_topology(rows: int, cols: int):
    """Spring index pairs by kind and the quads of a rows x cols grid (k = r cols + c)."""
    idx = np.arange(rows * cols).reshape(rows, cols)

    def pairs(a, b):
        return np.stack([a.ravel(), b.ravel()], axis=1)

    stretch = np.vstack([pairs(idx[:, :-1], idx[:, 1:]), pairs(idx[:-1, :], idx[1:, :])])
    shear = np.vstack([pairs(idx[:-1, :-1], idx[1:, 1:]), pairs(idx[:-1, 1:], idx[1:, :-1])])
    bend = np.vstack([pairs(idx[:, :-2], idx[:, 2:]), pairs(idx[:-2, :], idx[2:, :])])
    a, b, c, e = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    quads = np.stack([a, c, e, b], -1).reshape(-1, 4)
    return {STRETCH: stretch, SHEAR: shear, BEND: bend}, quads


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """The unique undirected edges ``(E, 2)``, smaller index first, of triangles ``faces``."""
    faces = np.asarray(faces, dtype=np.intp)
    return np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                             faces[:, [2, 0]]]), axis=1), axis=0)


def mesh_topology(faces: np.ndarray):
    """Stretch springs on the mesh edges, bend springs across each interior edge."""
    half = np.concatenate([faces[:, [0, 1, 2]], faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])
    edges = np.sort(half[:, :2], axis=1)  # each half-edge with its opposite vertex half[:, 2]
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, opposite = edges[order], half[order, 2]
    first = np.ones(len(edges), bool)
    first[1:] = np.any(edges[1:] != edges[:-1], axis=1)
    shared = np.flatnonzero(~first)  # second half-edge of an interior edge
    if np.any(np.bincount(np.cumsum(first) - 1) > 2):
        raise ValueError("non-manifold mesh: an edge is shared by more than two faces")
    bend = np.stack([opposite[shared - 1], opposite[shared]], axis=1)
    return {STRETCH: edges[first], SHEAR: np.zeros((0, 2), int), BEND: bend}


def lumped_masses(vertices: np.ndarray, faces: np.ndarray, total: float) -> np.ndarray:
    """Each vertex gets an equal share of the area of its polygons (triangles, or quads for
    a grid, which keeps a grid's masses symmetric); scaled to ``total`` kg."""
    k = faces.shape[1]
    a = vertices[faces[:, 0]]
    area = sum(0.5 * np.linalg.norm(np.cross(vertices[faces[:, q]] - a,
                                             vertices[faces[:, q + 1]] - a), axis=1)
               for q in range(1, k - 1))  # fan triangulation (planar, convex quads)
    share = np.bincount(faces.ravel(), np.repeat(area / k, k), minlength=len(vertices))
    if np.any(share <= 0):
        raise ValueError("every vertex must belong to a face of positive area "
                         "(remove unused vertices or degenerate triangles)")
    return total * share / share.sum()


def _symbolic_csc(pattern: BlockPattern, blocks) -> ca.SX:
    """The sparse SX matrix of a :class:`BlockPattern` filled with ``blocks`` (a column: the
    row-major blocks one after another, as the numeric route's data)."""
    size = pattern.size
    sparsity = ca.Sparsity(size, size, pattern.indptr.tolist(), pattern.indices.tolist())
    return ca.SX(sparsity, ca.mtimes(ca.DM(pattern.gather.tocsc()), blocks))


def pair_block_matrices(i: np.ndarray, j: np.ndarray, n: int, *blocks: np.ndarray) -> list:
    """One ``3n x 3n`` CSC matrix per ``(P, 9)`` row-major block array ``B``: ``-B`` at (i,i),
    (j,j) and ``+B`` at (i,j), (j,i), for pairs that change every step (self-contacts); the
    pattern is built once for all of them."""
    pattern = BlockPattern(i, j, n, particle_blocks=False)
    return [pattern.matrix(b) for b in blocks]


@dataclass(frozen=True)
class Attachment:
    """Particles led along a path: ``path(t)`` gives their ``(k, 3)`` positions at time t (s).

    The integrator sets their velocity each step so they reach ``path(t + dt)`` exactly.
    """

    particles: np.ndarray
    path: object

    def __post_init__(self):
        idx = np.atleast_1d(np.asarray(self.particles))
        if idx.dtype.kind not in "iu" or idx.size == 0:
            raise ValueError("Attachment particles must be a non-empty list of indices")
        object.__setattr__(self, "particles", idx.astype(np.intp))
        if not callable(self.path):
            raise ValueError("Attachment path must be a function of time t -> (k, 3) positions")
        self.positions(0.0)

    def positions(self, t: float) -> np.ndarray:
        p = np.asarray(self.path(t), dtype=float)
        if p.shape != (self.particles.size, 3) or not np.all(np.isfinite(p)):
            raise ValueError(f"Attachment path(t) must return finite ({self.particles.size}, 3) "
                             f"positions, got shape {p.shape}")
        return p


@dataclass(eq=False)
class ClothModel:
    """An immutable cloth of n particles with fixed springs; build with :meth:`grid` or
    :meth:`from_mesh`.  States are ``(n, 3)`` arrays; the flat 3n ordering is ``x.ravel()``.
    """

    rest_positions: np.ndarray
    faces: np.ndarray
    masses: np.ndarray
    springs: Springs
    params: ClothParams = field(default_factory=ClothParams)
    pinned: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    jit: bool | None = None
    colliders: tuple = ()
    self_contact: Contact | None = None
    attachments: tuple = ()
    dim: int = field(default=3, init=False)

    def __post_init__(self):
        if self.masses.shape != (len(self.rest_positions),) or np.any(self.masses <= 0):
            raise ValueError("masses must be positive, one per particle; build the cloth with "
                             "ClothModel.grid or ClothModel.from_mesh")
        self.pinned = _check_pinned(self.pinned, self.n)
        s, p = self.springs, self.params
        k_t = np.choose(s.kind, [p.stretch, p.shear, 0.0]).astype(float)
        k_t = np.where(s.kind == BEND, 24 * p.bend / s.rest ** 3, k_t)
        self._spring_params = [s.rest[:, None], k_t[:, None], np.full((s.rest.size, 1), p.bend),
                               np.full((s.rest.size, 1), p.damping)]
        self._kernels = spring_kernels(p.eps)
        self._springs = {k: MappedKernel(self._kernels[k], jit=self.jit) for k in KERNELS}
        self._pattern = BlockPattern(s.i, s.j, self.n)
        self._drag_blocks = np.outer(-p.air_drag * self.masses, np.eye(3).ravel())
        self._gravity = self.masses[:, None] * np.asarray(p.gravity)[None, :]
        self.colliders = tuple(self.colliders)
        for body in self.colliders:
            if not isinstance(body, Body):
                raise ValueError(f"colliders must be Plane, Sphere or Capsule bodies, got {body!r}")
        self._self = (None if self.self_contact is None else
                      SelfContact(self.self_contact, np.stack([s.i, s.j], 1), self.n))
        # mapped kernels of every collider and of self-contact (compiled at first use)
        self._bodies = tuple({k: MappedKernel(b.kernels[k], jit=self.jit) for k in KERNELS}
                             for b in self.colliders)
        self._distances = tuple(MappedKernel(b.kernels["distance"], jit=False)
                                for b in self.colliders)  # for reports: not worth compiling
        self._pairs = (None if self._self is None else
                       {k: MappedKernel(SelfContact.kernels[k], jit=self.jit) for k in KERNELS})
        self.attachments = tuple(self.attachments)
        constrained = np.concatenate([self.pinned] + [a.particles for a in self.attachments])
        if np.unique(constrained).size != constrained.size:
            raise ValueError("a particle is pinned or attached twice; give each one constraint")
        if constrained.size and constrained.max() >= self.n:
            raise ValueError(f"attached particle index out of range 0..{self.n - 1}")

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
        ``scene`` takes ``colliders``, ``self_contact`` and ``attachments`` (see the class).
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
        unknown = set(scene) - {"colliders", "self_contact", "attachments"}
        if unknown:
            raise TypeError(f"unknown cloth option(s) {sorted(unknown)}; scene options are "
                            "colliders, self_contact and attachments")
        return cls(vertices, faces, masses, springs, params, pinned, jit, **scene)

    @property
    def n(self) -> int:
        return len(self.masses)

    def free_mask(self) -> np.ndarray:
        """Boolean mask over the 3n velocity components: False for pinned and attached ones."""
        free = np.ones((self.n, 3), bool)
        free[self.pinned] = False
        for a in self.attachments:
            free[a.particles] = False
        return free.ravel()

    def prescribed_velocity(self, x: np.ndarray, t: float, dt: float) -> np.ndarray:
        """``(n, 3)`` velocities at the end of the step from time t: zero for pinned particles,
        ``(path(t + dt) - x) / dt`` for attached ones (zero for free particles, unused)."""
        out = np.zeros((self.n, 3))
        for a in self.attachments:
            out[a.particles] = (a.positions(t + dt) - x[a.particles]) / dt
        return out

    def attachment_targets(self, t: float) -> np.ndarray:
        """Positions of every attached particle at time t, flat (attachment order)."""
        return np.concatenate([a.positions(t).ravel() for a in self.attachments] or [np.zeros(0)])

    def scene_parameters(self, t: float) -> np.ndarray:
        """The colliders' geometry at time t as one flat vector (``S`` of the symbolic forces)."""
        return np.concatenate([b.parameters(t) for b in self.colliders] or [np.zeros(0)])

    def max_stretch(self, x: np.ndarray) -> float:
        """The largest spring length over rest length (1 at rest); a blow-up shows here first."""
        s = self.springs
        return float((np.linalg.norm(pair_difference(x, s.i, s.j), axis=1) / s.rest).max())

    def penetration(self, x: np.ndarray, t: float = 0.0) -> float:
        """How deep (m) the deepest particle is inside a collider at time t (0 if none is)."""
        deepest = 0.0
        for body, kernel in zip(self.colliders, self._distances):
            (phi,) = kernel(x, np.zeros_like(x), *body.inputs(self.n, t))
            deepest = max(deepest, float(-phi.min()))
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

    @functools.cached_property
    def step_pattern(self) -> BlockPattern:
        """The springs' :class:`~.blocks.BlockPattern` restricted to the free components: the
        structure of an implicit step matrix's free block without self-contact (built once:
        it depends on the springs and constraints only)."""
        s = self.springs
        return BlockPattern(s.i, s.j, self.n, self.free_mask())

    # -- numeric -------------------------------------------------------------------------
    def interactions(self, x: np.ndarray):
        """What the forces at positions x act over beyond the fixed springs: the self-contact
        pairs ``(i, j)`` (None without self-contact).  Found once per state and passed to
        :meth:`forces`, :meth:`jacobians` and the step derivatives, which otherwise search
        again."""
        return None if self._self is None else self._self.pairs(x)

    def _contacts(self, x, interactions):
        if self._self is None:
            return None
        i, j = self._self.pairs(x) if interactions is None else interactions
        return (i, j) if i.size else None

    def _spring_inputs(self, x, v):
        x, v = self._check_state(x, "x"), self._check_state(v, "v")
        s = self.springs
        return [pair_difference(x, s.i, s.j), pair_difference(v, s.i, s.j), *self._spring_params]

    def spring_forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Internal spring forces (elastic + damping) on every particle, ``(n, 3)`` N."""
        (fs,) = self._springs["force"](*self._spring_inputs(x, v))
        return scatter_pairs(fs, self.springs.i, self.springs.j, self.n)

    def contact_forces(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
                       interactions=None) -> np.ndarray:
        """Forces of the colliders at time t and of self-contact, ``(n, 3)`` N."""
        out = np.zeros((self.n, 3))
        for body, kernels in zip(self.colliders, self._bodies):
            out += kernels["force"](x, v, *body.inputs(self.n, t))[0]
        pairs = self._contacts(x, interactions)
        if pairs is not None:
            (fp,) = self._pairs["force"](*self._self.inputs(x, v, *pairs))
            out += scatter_pairs(fp, *pairs, self.n)
        return out

    def forces(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
               interactions=None) -> np.ndarray:
        """Total force ``(n, 3)`` N at time t: springs + gravity ``m_i g`` + drag
        ``-air_drag m_i v_i`` + contacts (self-contact over ``interactions``, default: those
        of x)."""
        drag = self.params.air_drag * self.masses[:, None] * np.asarray(v, dtype=float)
        out = self.spring_forces(x, v) + self._gravity - drag
        if self.colliders or self._self is not None:
            out += self.contact_forces(x, v, t, interactions)
        return out

    def jacobian_blocks(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
                        with_df_dx: bool = False, interactions=None) -> tuple[Blocks, ...]:
        """:meth:`jacobians` as :class:`~.blocks.Blocks` over the springs followed by the
        self-contact pairs (``interactions``, default: those of x)."""
        return self._blocks(x, v, t, interactions, ("jac", "df_dx") if with_df_dx else ("jac",))

    def force_jacobian_blocks(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
                              interactions=None) -> Blocks:
        """The full ``df/dx`` alone as :class:`~.blocks.Blocks` (what the swapped adjoint
        needs when the step matrix's factor is already at hand)."""
        return self._blocks(x, v, t, interactions, ("df_dx",))[0]

    def _blocks(self, x, v, t, interactions, kinds) -> tuple[Blocks, ...]:
        """The blocks of kernels ``kinds`` ("jac": K and D, "df_dx": J) of every interaction."""
        inputs = self._spring_inputs(x, v)
        pairs = [b for kind in kinds for b in self._springs[kind](*inputs)]
        start = {"jac": [np.zeros((self.n, 9)), self._drag_blocks.copy()],
                 "df_dx": [np.zeros((self.n, 9))]}
        particles = [b for kind in kinds for b in start[kind]]
        for body, kernels in zip(self.colliders, self._bodies):
            columns = body.inputs(self.n, t)
            blocks = [b for kind in kinds for b in kernels[kind](x, v, *columns)]
            for acc, b in zip(particles, blocks):
                acc += b
        i, j = self.springs.i, self.springs.j
        contacts = self._contacts(x, interactions)
        if contacts is not None:
            columns = self._self.inputs(x, v, *contacts)
            blocks = [b for kind in kinds for b in self._pairs[kind](*columns)]
            pairs = [np.vstack([a, b]) for a, b in zip(pairs, blocks)]
            i, j = np.concatenate([i, contacts[0]]), np.concatenate([j, contacts[1]])
        return tuple(Blocks(i, j, p, q) for p, q in zip(pairs, particles))

    def jacobians(self, x: np.ndarray, v: np.ndarray, t: float = 0.0, with_df_dx: bool = False,
                  interactions=None):
        """``(K, D)`` as 3n x 3n CSC matrices at time t, both symmetric, ``-K`` and ``-D``
        positive semi-definite; with ``with_df_dx`` also the full ``df/dx`` (not symmetric).

        ``D = df/dv``.  K is the stiffness the implicit step uses: ``df/dx`` at zero velocity
        (damping's position derivative omitted, as in Baraff-Witkin) without the transverse
        term of compressed springs and the curvature of contact surfaces
        (:func:`spring_law`, :func:`.colliders.penalty_law`).  The adjoints of full backward
        Euler (exact and swapped) need the true ``df/dx``, damping's part included.
        """
        blocks = self.jacobian_blocks(x, v, t, with_df_dx, interactions)
        S = self.springs.i.size
        out = [self._pattern.matrix(b.pairs[:S], b.particles) for b in blocks]
        i, j = blocks[0].i[S:], blocks[0].j[S:]
        if i.size:
            contact = pair_block_matrices(i, j, self.n, *(b.pairs[S:] for b in blocks))
            out = [a + b for a, b in zip(out, contact)]
        return tuple(out)

    def linearization_vjp(self, x, v, t: float, lam, w, q, dt: float, interactions=None):
        """Gradients ``(gx, gv)``, each ``(n, 3)``, of ``lam . (dt f + dt^2 K w + dt D q)`` in
        x and v at time t: what the exact adjoint of a linearized implicit step needs,
        second derivatives of every force law contracted per interaction (``lam, w, q``
        are ``(n, 3)``).  Drag is linear in v and its part is added here too."""
        s = self.springs
        inputs = self._spring_inputs(x, v)
        pair_vectors = [pair_difference(a, s.i, s.j) for a in (-lam, w, q)]
        gd, gdv = self._springs["vjp"](*inputs, *pair_vectors, np.full((s.i.size, 1), dt))
        gx = -scatter_pairs(gd, s.i, s.j, self.n)  # d = x_j - x_i
        gv = -scatter_pairs(gdv, s.i, s.j, self.n) - dt * self.params.air_drag * (
            self.masses[:, None] * lam)
        dts = np.full((self.n, 1), dt)
        for body, kernels in zip(self.colliders, self._bodies):
            bx, bv = kernels["vjp"](x, v, *body.inputs(self.n, t), lam, w, q, dts)
            gx, gv = gx + bx, gv + bv
        contacts = self._contacts(x, interactions)
        if contacts is not None:
            i, j = contacts
            vectors = [pair_difference(a, i, j) for a in (-lam, w, q)]
            px, pv = self._pairs["vjp"](*self._self.inputs(x, v, i, j), *vectors,
                                        np.full((i.size, 1), dt))
            gx, gv = gx - scatter_pairs(px, i, j, self.n), gv - scatter_pairs(pv, i, j, self.n)
        return gx, gv

    def linearization_jvp(self, x, v, t: float, w, q, dt: float, dx, dv, interactions=None):
        """The other side of :meth:`linearization_vjp`: the derivative of
        ``dt f + dt^2 K w + dt D q`` at time t along ``(dx, dv)``, ``(n, 3)``; what the
        tangent of a linearized implicit step needs, second derivatives contracted per
        interaction."""
        s = self.springs
        inputs = self._spring_inputs(x, v)
        pair_vectors = [pair_difference(a, s.i, s.j) for a in (w, q)]
        deltas = [pair_difference(a, s.i, s.j) for a in (dx, dv)]
        (dg,) = self._springs["jvp"](*inputs, *pair_vectors, np.full((s.i.size, 1), dt), *deltas)
        out = scatter_pairs(dg, s.i, s.j, self.n) - dt * self.params.air_drag * (
            self.masses[:, None] * dv)
        dts = np.full((self.n, 1), dt)
        for body, kernels in zip(self.colliders, self._bodies):
            out += kernels["jvp"](x, v, *body.inputs(self.n, t), w, q, dts, dx, dv)[0]
        contacts = self._contacts(x, interactions)
        if contacts is not None:
            i, j = contacts
            vectors = [pair_difference(a, i, j) for a in (w, q, dx, dv)]
            (dp,) = self._pairs["jvp"](*self._self.inputs(x, v, i, j), *vectors[:2],
                                       np.full((i.size, 1), dt), *vectors[2:])
            out += scatter_pairs(dp, i, j, self.n)
        return out

    # -- symbolic ------------------------------------------------------------------------
    def symbolic_forces(self, X, V, S=None):
        """:meth:`forces` as a CasADi expression; X, V are ``3 x n`` (column k = particle k)
        and S the :meth:`scene_parameters` (default: those at t = 0).  Self-contact is
        evaluated over all unjoined pairs: for small systems."""
        s, P = self.springs, self.springs.i.size
        params = [ca.DM(a.T) for a in self._spring_params]
        fs = self._kernels["force"].map(P)(X[:, s.j] - X[:, s.i], V[:, s.j] - V[:, s.i], *params)
        out = ca.mtimes(fs, pair_incidence(s.i, s.j, self.n)) + ca.DM(self._gravity.T)
        out -= self.params.air_drag * V * ca.repmat(ca.DM(self.masses).T, 3, 1)
        for body, part in self._scene_parts(S):
            out += body.symbolic("force", X, V, part)[0]
        if self._self is not None:
            i, j, gains = self._symbolic_pairs()
            fp = SelfContact.kernels["force"].map(i.size)(X[:, j] - X[:, i], V[:, j] - V[:, i],
                                                          gains)
            out += ca.mtimes(fp, pair_incidence(i, j, self.n))
        return out

    def symbolic_jacobians(self, X, V, S=None):
        """:meth:`jacobians` as sparse CasADi expressions ``(K, D)``, assembled from the same
        kernels and pattern (so K is the step's clamped stiffness, not ``df/dx``)."""
        s, P = self.springs, self.springs.i.size
        params = [ca.DM(a.T) for a in self._spring_params]
        kp, dp = self._kernels["jac"].map(P)(X[:, s.j] - X[:, s.i], V[:, s.j] - V[:, s.i],
                                             *params)
        k_blocks, d_blocks = ca.SX.zeros(9, self.n), ca.SX(ca.DM(self._drag_blocks.T))
        for body, part in self._scene_parts(S):
            kb, db = body.symbolic("jac", X, V, part)
            k_blocks, d_blocks = k_blocks + kb, d_blocks + db
        K = _symbolic_csc(self._pattern, ca.vertcat(ca.vec(kp), ca.vec(k_blocks)))
        D = _symbolic_csc(self._pattern, ca.vertcat(ca.vec(dp), ca.vec(d_blocks)))
        if self._self is not None:
            i, j, gains = self._symbolic_pairs()
            kc, dc = SelfContact.kernels["jac"].map(i.size)(X[:, j] - X[:, i],
                                                           V[:, j] - V[:, i], gains)
            pattern = BlockPattern(i, j, self.n, particle_blocks=False)
            K += _symbolic_csc(pattern, ca.vec(kc))
            D += _symbolic_csc(pattern, ca.vec(dc))
        return K, D

    def _scene_parts(self, S):
        """Each collider with its slice of the scene parameters S (default: those at t = 0)."""
        S = ca.DM(self.scene_parameters(0.0)) if S is None else S
        at = 0
        for body in self.colliders:
            size = body.parameters(0.0).size
            yield body, S[at:at + size]
            at += size

    def _symbolic_pairs(self):
        i, j = self._self.all_pairs()
        return i, j, ca.repmat(ca.DM(self._self.contact.gains), 1, i.size)

    def _check_state(self, a, name: str) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.shape != (self.n, 3):
            raise ValueError(f"{name} must have shape ({self.n}, 3), got {a.shape}")
        return a


def _total_mass(mass) -> bool:
    if not (np.isscalar(mass) and np.isfinite(mass) and mass > 0):
        raise ValueError(f"the cloth's total mass must be a positive finite number, got {mass}")
    return True


def _check_vector(value, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value}")
    return a


def _check_pinned(pinned, n: int) -> np.ndarray:
    if not np.size(pinned):
        return np.zeros(0, np.intp)
    p = np.unique(np.asarray(pinned, dtype=np.intp).ravel())
    if p.size and (p.min() < 0 or p.max() >= n):
        raise ValueError(f"pinned particle indices must be in 0..{n - 1}, got {p.min()}..{p.max()}")
    return p
