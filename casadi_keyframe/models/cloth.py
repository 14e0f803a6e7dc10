r"""Mass-spring cloth in 3-D: a list of interaction families summed once per method.

A cloth's forces are the families of :mod:`.interaction`, in this order: its springs
(:class:`~.springs.ChoiKoSprings`), gravity and air drag
(:class:`~.gravity_drag.GravityAndDrag`), the contact of each collider (the paper's penalty springs,
:class:`~.penalty.BodyPenalty`, guarded by the step holding particles on the body's surface,
:class:`~.contact_constraint.BodyConstraint`; or either alone), self-contact (:class:`~.self_contact.SelfContact`) and any
further ``families`` given.  :class:`ClothModel` sums them in each method (forces, Jacobian
blocks, the linearization's derivative contractions, their symbolic forms) and owns its
constraints (:mod:`.constraints`: pinned and attached particles) and its reports (stretch,
penetration).  A new force law or contact model is one family file plus one entry here.

Jacobian blocks: a pair family adds ``-B`` to blocks (i, i), (j, j) and ``+B`` to (i, j),
(j, i) of a Jacobian, a particle family a diagonal block (:mod:`.blocks`).  The springs'
pattern and its restriction to the free components (:attr:`ClothModel.step_pattern`) are
built once; pairs found per state (self-contact) follow the fixed ones.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..state import SimulationError
from .base import BlockJacobians, Model, PhysicalReport, Surface
from .blocks import BlockPattern, Blocks, pair_block_matrices
from .colliders import Body, Contact, signed_distances
from .constraints import Constraints
from .contact_constraint import BodyConstraint, HeldContacts
from .gravity_drag import GravityAndDrag
from .interaction import OUTPUTS, Interaction, PairInteraction
from .penalty import BodyPenalty
from .self_contact import SelfContact
from .springs import ChoiKoSprings, Springs
from .topology import grid_topology, lumped_masses, mesh_topology

PLANES = ("xz", "xy")
COLLISIONS = {  # how bodies are touched: each body's families
    "guarded": lambda body, n, jit: (BodyPenalty(body, n, jit),
                                     BodyConstraint(body, n, jit, layer=0.0)),
    "constraint": lambda body, n, jit: (BodyConstraint(body, n, jit),),
    "penalty": lambda body, n, jit: (BodyPenalty(body, n, jit),),
}


@dataclass(frozen=True)
class ClothParams:
    """Cloth material, SI units; defaults suit a ~1 m, ~0.3 kg sheet at dt = 1/60..1/30 s.

    ``stretch``, ``shear``: linear tension stiffness per spring, N/m (on a square grid the
    sheet's membrane stiffness does not depend on the resolution).  ``bend``: buckling
    stiffness ``k_b``, N m^2.  ``damping``: along-spring damping c, N s/m.  ``air_drag``:
    drag per unit mass, 1/s.  ``gravity``: m/s^2.  ``eps``: length regularisation, m.
    ``blowup_stretch``: a spring this many times its rest length means a step has failed.
    """

    stretch: float = 500.0
    shear: float = 50.0
    bend: float = 2e-5
    damping: float = 0.02
    air_drag: float = 0.1
    gravity: tuple = (0.0, 0.0, -9.81)
    eps: float = 1e-6
    blowup_stretch: float = 5.0

    def __post_init__(self):
        for name in ("stretch", "shear", "bend", "damping", "air_drag"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"ClothParams.{name} must be non-negative and finite, got {value}")
        if not self.eps > 0:
            raise ValueError(f"ClothParams.eps must be positive, got {self.eps}")
        if not self.blowup_stretch > 1:
            raise ValueError(f"ClothParams.blowup_stretch must be > 1, got {self.blowup_stretch}")
        g = tuple(float(c) for c in self.gravity)
        if len(g) != 3 or not np.all(np.isfinite(g)):
            raise ValueError(f"ClothParams.gravity must be 3 finite numbers, got {self.gravity}")
        object.__setattr__(self, "gravity", g)


def _frozen(*arrays):
    for a in arrays:
        a.flags.writeable = False


class ClothModel(Model, BlockJacobians, HeldContacts, PhysicalReport, Surface):
    """An immutable cloth of n particles with fixed springs; build with :meth:`grid` or
    :meth:`from_mesh`.  States are ``(n, 3)`` arrays; the flat 3n ordering is ``x.ravel()``.

    ``colliders``: bodies the cloth touches (``collision``): by default the paper's stiff
    springs in the contact layer with the step holding every particle on the body's surface,
    so none passes through (``"guarded"``); the step holding particles on the layer's surface
    with no spring (``"constraint"``); or the springs alone (``"penalty"``, the paper's);
    ``self_contact``: the :class:`~.colliders.Contact` of cloth with itself (penalty; None:
    none); ``attachments``: particles led along paths; ``families``: further interaction
    families, summed after the others.
    """

    dim = 3

    def __init__(self, rest_positions, faces, masses, springs: Springs,
                 params: ClothParams | None = None, pinned=(), jit: bool | None = None,
                 colliders=(), self_contact: Contact | None = None, attachments=(),
                 families=(), collision: str = "guarded"):
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
        if collision not in COLLISIONS:
            raise ValueError(f"collision must be one of {sorted(COLLISIONS)} (contact held by "
                             f"the step, or the paper's penalty springs), got {collision!r}")
        families = tuple(families)
        for family in families:
            if not isinstance(family, Interaction):
                raise ValueError(f"families must be Interaction objects, got {family!r}")
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
                                      damping=params.damping, eps=params.eps, jit=jit)
        self_family = (() if self_contact is None else
                       (SelfContact(self_contact, np.stack([springs.i, springs.j], 1), n, jit),))
        set_("families", (spring_family, GravityAndDrag(self.masses, params.gravity,
                                                        params.air_drag),
                          *(f for body in colliders for f in COLLISIONS[collision](body, n, jit)),
                          *self_family, *families))
        set_("_pattern", BlockPattern(springs.i, springs.j, n))
        set_("_step_pattern", None)

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

    def family(self, name: str) -> Interaction:
        """The first interaction family named ``name`` (e.g. "self-contact")."""
        for family in self.families:
            if family.name == name:
                return family
        raise KeyError(f"this cloth has no {name!r} family; it has "
                       f"{[f.name for f in self.families]}")

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

    def scene_parameters(self, t: float) -> np.ndarray:
        """Every family's time-dependent inputs at time t as one flat vector (the symbolic S:
        the colliders' geometry)."""
        return np.concatenate([f.parameters(t) for f in self.families])

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

    @property
    def step_pattern(self) -> BlockPattern:
        """The springs' :class:`~.blocks.BlockPattern` restricted to the free components: the
        structure of an implicit step matrix's free block without self-contact (built at
        first use; it depends on the springs and constraints, which never change)."""
        if self._step_pattern is None:
            s = self.springs
            object.__setattr__(self, "_step_pattern",
                               BlockPattern(s.i, s.j, self.n, self.free_mask()))
        return self._step_pattern

    # -- numeric: the families summed ----------------------------------------------------
    def interactions(self, x: np.ndarray) -> tuple:
        """What each family acts over at positions x beyond its fixed structure (self-contact
        pairs; None for the others), found once per state and passed to :meth:`forces`,
        :meth:`jacobians` and the step derivatives, which otherwise search again."""
        return tuple(f.find(x) for f in self.families)

    def _found(self, x, interactions):
        return self.interactions(x) if interactions is None else interactions

    def forces(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
               interactions=None, role: str | None = None) -> np.ndarray:
        """Total force ``(n, 3)`` N at time t: every family's, summed (with ``role``, only
        those of that role: "internal", "external" or "contact")."""
        x, v = self._check_state(x, "x"), self._check_state(v, "v")
        out, contact = np.zeros((self.n, 3)), None
        for family, found in zip(self.families, self._found(x, interactions)):
            if role is not None and family.role != role:
                continue
            if family.role == "contact" and role is None:  # summed apart, then added: the
                # order results were computed in before the families were units
                contact = np.zeros((self.n, 3)) if contact is None else contact
                family.add_forces(contact, x, v, t, found)
            else:
                family.add_forces(out, x, v, t, found)
        if contact is not None:
            out += contact
        return out

    def jacobian_blocks(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
                        with_df_dx: bool = False, interactions=None) -> tuple[Blocks, ...]:
        """``(K, D[, J])`` (see :meth:`jacobians`) as :class:`~.blocks.Blocks` over the
        springs followed by the pairs found at x (self-contact)."""
        return self._blocks(x, v, t, interactions, ("jac", "df_dx") if with_df_dx else ("jac",))

    def force_jacobian_blocks(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
                              interactions=None) -> Blocks:
        """The full ``df/dx`` alone as :class:`~.blocks.Blocks` (what the swapped adjoint
        needs when the step matrix's factor is already at hand)."""
        return self._blocks(x, v, t, interactions, ("df_dx",))[0]

    def _blocks(self, x, v, t, interactions, kinds) -> tuple[Blocks, ...]:
        """The blocks of kernels ``kinds`` ("jac": K and D, "df_dx": J) of every family."""
        x, v = self._check_state(x, "x"), self._check_state(v, "v")
        width = sum(OUTPUTS[k] for k in kinds)
        fixed, found_pairs = [], []  # (i, j, blocks) of pair families
        particles = [np.zeros((self.n, 9)) for _ in range(width)]
        for family, found in zip(self.families, self._found(x, interactions)):
            part = family.blocks(x, v, t, kinds, found)
            if part.pairs is not None:
                group = fixed if family.fixed_pairs else found_pairs
                group.append((part.i, part.j, part.pairs))
            for acc, b in zip(particles, part.particles or ()):
                if b is not None:
                    acc += b
        groups = fixed + found_pairs
        if len(groups) == 1:
            i, j, pairs = groups[0]
        else:
            i = np.concatenate([g[0] for g in groups])
            j = np.concatenate([g[1] for g in groups])
            pairs = [np.vstack([g[2][k] for g in groups]) for k in range(width)]
        return tuple(Blocks(i, j, p, q) for p, q in zip(pairs, particles))

    def jacobians(self, x: np.ndarray, v: np.ndarray, t: float = 0.0, with_df_dx: bool = False,
                  interactions=None):
        """``(K, D)`` as 3n x 3n CSC matrices at time t, both symmetric, ``-K`` and ``-D``
        positive semi-definite; with ``with_df_dx`` also the full ``df/dx`` (not symmetric).

        ``D = df/dv``.  K is the stiffness the implicit step uses: ``df/dx`` at zero velocity
        (damping's position derivative omitted, as in Baraff-Witkin) without the transverse
        term of compressed springs and the curvature of contact surfaces
        (:func:`.springs.spring_law`, :func:`.penalty.penalty_law`).  The adjoints of full
        backward Euler (exact and swapped) need the true ``df/dx``, damping's part included.
        """
        blocks = self.jacobian_blocks(x, v, t, with_df_dx, interactions)
        S = self.springs.i.size
        out = [self._pattern.matrix(b.pairs[:S], b.particles) for b in blocks]
        i, j = blocks[0].i[S:], blocks[0].j[S:]
        if i.size:
            extra = pair_block_matrices(i, j, self.n, *(b.pairs[S:] for b in blocks))
            out = [a + b for a, b in zip(out, extra)]
        return tuple(out)

    def linearization_vjp(self, x, v, t: float, lam, w, q, dt: float, interactions=None):
        """Gradients ``(gx, gv)``, each ``(n, 3)``, of ``lam . (dt f + dt^2 K w + dt D q)`` in
        x and v at time t: what the exact adjoint of a linearized implicit step needs,
        second derivatives of every force law contracted per interaction (``lam, w, q``
        are ``(n, 3)``)."""
        gx, gv = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        for family, found in zip(self.families, self._found(x, interactions)):
            out = family.linearization_vjp(x, v, t, lam, w, q, dt, found)
            if out is not None:
                bx, bv = out
                if bx is not None:
                    gx += bx
                gv += bv
        return gx, gv

    def linearization_jvp(self, x, v, t: float, w, q, dt: float, dx, dv, interactions=None):
        """The other side of :meth:`linearization_vjp`: the derivative of
        ``dt f + dt^2 K w + dt D q`` at time t along ``(dx, dv)``, ``(n, 3)``; what the
        tangent of a linearized implicit step needs, second derivatives contracted per
        interaction."""
        out = np.zeros((self.n, 3))
        for family, found in zip(self.families, self._found(x, interactions)):
            dg = family.linearization_jvp(x, v, t, w, q, dt, dx, dv, found)
            if dg is not None:
                out += dg
        return out

    # -- symbolic ------------------------------------------------------------------------
    def symbolic_forces(self, X, V, S=None):
        """:meth:`forces` as a CasADi expression; X, V are ``3 x n`` (column k = particle k)
        and S the :meth:`scene_parameters` (default: those at t = 0).  Pair families act over
        every pair they might (self-contact: all unjoined pairs): for small systems."""
        out = 0
        for family, part in self.scene_parts(S):
            out += family.symbolic_forces(X, V, part)
        return out

    def decision_parameters(self, found=None) -> np.ndarray:
        """What a step decided for each family (``found``, from its record; None: nothing
        beyond the state) as the flat inputs :meth:`symbolic_jacobians` takes."""
        found = (None,) * len(self.families) if found is None else found
        return np.concatenate([f.decisions(d) for f, d in zip(self.families, found)])

    def carried_decisions(self, found):
        """The springs a step took taut (its other decisions come again from x)."""
        if found is None:
            return None
        return tuple(d if isinstance(f, ChoiKoSprings) else None
                     for f, d in zip(self.families, found))

    def carried_interactions(self, last, x):
        found = self.interactions(x)
        if last is None:
            return found
        return tuple(f.carried(d, x) if isinstance(f, ChoiKoSprings) else new
                     for f, d, new in zip(self.families, last, found))

    def revised_interactions(self, found, x0, x1):
        """``found`` with what a step from x0 that ended at x1 shows it should have decided
        (springs it should have taken taut); None if nothing changes."""
        out, changed = list(found), False
        for k, family in enumerate(self.families):
            if isinstance(family, ChoiKoSprings):
                new = family.revised(found[k], x0, x1)
                if new is not None:
                    out[k], changed = new, True
        return tuple(out) if changed else None

    def symbolic_jacobians(self, X, V, S=None, decisions=None):
        """:meth:`jacobians` as sparse CasADi expressions ``(K, D)``, assembled from the same
        kernels and patterns (so K is the step's clamped stiffness, not ``df/dx``), given the
        step's ``decisions`` (:meth:`decision_parameters`; None: nothing)."""
        zeros = ca.SX.zeros(9, self.n)
        particles, fixed, extra = [zeros, zeros], None, []
        at = 0
        for family, part in self.scene_parts(S):
            size = family.decision_size()
            mine = None if decisions is None or not size else decisions[at:at + size]
            at += size
            blocks = family.symbolic_blocks(X, V, part, mine)
            for k, b in enumerate(blocks.particles or ()):
                if b is not None:
                    particles[k] = particles[k] + b
            if blocks.pairs is None:
                continue
            if isinstance(family, PairInteraction) and family is self.families[0]:
                fixed = blocks.pairs  # the springs: in the model's own pattern
            else:
                extra.append(blocks)
        K, D = (_symbolic_csc(self._pattern, ca.vertcat(ca.vec(fixed[k]), ca.vec(particles[k])))
                for k in range(2))
        for blocks in extra:
            pattern = BlockPattern(blocks.i, blocks.j, self.n, particle_blocks=False)
            K += _symbolic_csc(pattern, ca.vec(blocks.pairs[0]))
            D += _symbolic_csc(pattern, ca.vec(blocks.pairs[1]))
        return K, D

    def scene_parts(self, S):
        """Each family with its slice of the scene parameters S (default: those at t = 0)."""
        S = ca.DM(self.scene_parameters(0.0)) if S is None else S
        at = 0
        for family in self.families:
            size = family.parameters(0.0).size
            yield family, S[at:at + size]
            at += size

    def _check_state(self, a, name: str) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.shape != (self.n, 3):
            raise ValueError(f"{name} must have shape ({self.n}, 3), got {a.shape}")
        return a


def _symbolic_csc(pattern: BlockPattern, blocks) -> ca.SX:
    """The sparse SX matrix of a :class:`BlockPattern` filled with ``blocks`` (a column: the
    row-major blocks one after another, as the numeric route's data)."""
    size = pattern.size
    sparsity = ca.Sparsity(size, size, pattern.indptr.tolist(), pattern.indices.tolist())
    return ca.SX(sparsity, ca.mtimes(ca.DM(pattern.gather.tocsc()), blocks))


def _total_mass(mass) -> bool:
    if not (np.isscalar(mass) and np.isfinite(mass) and mass > 0):
        raise ValueError(f"the cloth's total mass must be a positive finite number, got {mass}")
    return True


def _check_vector(value, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value}")
    return a
