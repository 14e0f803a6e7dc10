r"""An interaction family: one force law acting over many interactions of a particle system
(the springs, a dihedral bending, one body's penalty contact, the step's hold, self-contact,
gravity and drag), as a unit.

A family gives, at ``x, v`` (``(n, 3)``) at time t, what an implicit step and its exact
derivatives need, and the same in CasADi: :meth:`~Interaction.forces`;
:meth:`~Interaction.blocks`, its Jacobians as 3x3 blocks ("jac": the step's stiffness K and
damping D; "df_dx": the full J); :meth:`~Interaction.linearization_vjp` and ``_jvp``, the
second derivatives contracted per interaction (:func:`~..kernels.interaction_kernels`); and
:meth:`~Interaction.symbolic_forces`, ``symbolic_blocks`` of ``3 x n`` X, V and its scene
parameters (:meth:`~Interaction.parameters`).

What a family acts over or decides per step is its ``found``, given back to every method:
what :meth:`find` sees at x (self-contact's pairs), or what a step decides (:meth:`decide`),
learns from its solve (:meth:`solved`), revises at its end (:meth:`stops`, :meth:`revise`)
or settles when the step stands (:meth:`settle`), carries to the next (:meth:`carry`) and
gives the symbolic step (:meth:`decision_parameters`): the springs taken taut, the particles the hold holds.

Three shapes of family, after jax-md's split of a law and its lifting: a
:class:`PairInteraction` lifts a kernel of ``d = x_j - x_i`` over pairs (``+f`` on i, ``-f``
on j), a :class:`ParticleInteraction` a kernel of one particle over every particle, a
:class:`StencilInteraction` a kernel of k particles over fixed stencils.  A new force law
is one file with one such class, given to a model as one list entry.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..kernels import (MappedKernel, pair_difference, pair_incidence, scatter_pairs,
                       scatter_stencils, stencil_incidence, stencil_values)

KERNELS = ("force", "jac", "df_dx", "vjp", "jvp")  # every family's, see interaction_kernels
OUTPUTS = {"jac": 2, "df_dx": 1}  # blocks per kernel: (K, D) and J


@dataclass(frozen=True)
class FamilyBlocks:
    """One family's Jacobian blocks for the kernels asked (in order, ``(K, D)`` for "jac",
    ``J`` for "df_dx"): ``pairs`` ``(P, 9)`` arrays over the pairs ``(i, j)``, ``particles``
    ``(n, 9)`` arrays on the diagonal, ``stencil_blocks`` ``(P, 9 k^2)`` arrays over the
    ``(P, k)`` ``stencil``; each None when the family has none."""

    i: np.ndarray | None = None
    j: np.ndarray | None = None
    pairs: tuple | None = None
    particles: tuple | None = None
    stencil: np.ndarray | None = None
    stencil_blocks: tuple | None = None


@dataclass(frozen=True)
class StepSpan:
    """A step as a family's decisions see it: from ``(x, v)`` at ``t`` over ``dt``; ``free``
    ``(n,)`` the particles without prescribed motion; ``x1`` where it ended (None at its
    start).  :meth:`distances` keeps each body's signed distances at x1 for the families
    that ask, :meth:`kept` any other such figure."""

    x: np.ndarray
    v: np.ndarray
    t: float
    dt: float
    free: np.ndarray
    x1: np.ndarray | None = None
    _kept: dict = field(default_factory=dict, repr=False, compare=False)

    def distances(self, body) -> np.ndarray:
        """Every particle's signed distance to ``body`` at the step's end (x1, t + dt),
        exact within the body's reach (:meth:`~.contact.colliders.Body.reach`) of the
        velocities the step ended with, beyond it beyond."""
        reach = body.reach((self.x1 - self.x) / self.dt, self.t + self.dt, self.dt)
        return self.kept(("distances", id(body)),
                         lambda: body.signed_distances(self.x1, self.t + self.dt, reach))

    def kept(self, key, compute):
        """``compute()``, computed once for this span and ``key`` (what the families
        deciding on it share)."""
        if key not in self._kept:
            self._kept[key] = compute()
        return self._kept[key]


class Interaction:
    """Base of a family (module docstring); subclasses give the numeric and symbolic forms.

    ``name`` says what the family is; ``role`` what kind of force it is: "internal" (sums to
    zero: springs, bending), "external" (gravity, drag) or "contact" (bodies, self-contact);
    ``holds`` whether its decision is a set the step's solve holds (:mod:`.contact.hold`)."""

    name = "interaction"
    role = "external"
    holds = False

    def find(self, x: np.ndarray):
        """What the family acts over at positions x beyond its fixed structure (None: fixed)."""
        return None

    def parameters(self, t: float) -> np.ndarray:
        """The family's time-dependent inputs at time t as one flat vector (the symbolic S)."""
        return np.zeros(0)

    def structure(self) -> tuple:
        """``((i, j), stencils)``: the pairs and the ``(P, k)`` stencils its blocks occupy
        at every state (a step matrix's fixed pattern), each None if none."""
        return None, None

    # -- what a step decides for the family and carries to the next ----------------------
    def decide(self, step: StepSpan, carried):
        """The family's ``found`` for a step starting at ``step`` after one that left
        ``carried`` (:meth:`carry`; None at a run's start): here, :meth:`find`."""
        return self.find(step.x)

    def stops(self, found, end: StepSpan) -> bool:
        """Whether the family stopped particles within the step that ended at ``end.x1``
        (the hold does): what a stop may break is then revised (:meth:`revise`)."""
        return False

    def revise(self, found, end: StepSpan, stopped: bool):
        """``found`` revised after the step ended at ``end.x1`` when the end shows it chose
        wrong (``stopped``: some family stopped particles), None if it stands (here)."""
        return None

    def settle(self, found, end: StepSpan, stopped: bool):
        """``found`` of a step that stands, with what its end leaves to the next step (the
        springs: those to take taut from then on); here, unchanged."""
        return found

    def solved(self, found, residual: np.ndarray):
        """``found`` given the solved step's residual ``A dv - b`` (flat; the hold's
        impulses): here, unchanged."""
        return found

    def carry(self, found):
        """What the next step takes from this one's ``found``: plain arrays, tuples and None,
        equal exactly when it decides the same (None here: nothing)."""
        return None

    def decision_parameters(self, found, t: float, dt: float) -> np.ndarray:
        """What a step from t decided (``found``, None: nothing) as the flat inputs of its
        symbolic forms (none here: see the springs' taut flags, the hold's held set)."""
        return np.zeros(0)

    def decision_size(self) -> int:
        return self.decision_parameters(None, 0.0, 1.0).size

    # -- the law -------------------------------------------------------------------------
    def forces(self, x, v, t: float, found) -> np.ndarray | None:
        """Its force on every particle, ``(n, 3)`` (None: none acts now)."""
        raise NotImplementedError

    def add_forces(self, out: np.ndarray, x, v, t: float, found) -> None:
        """Add :meth:`forces` into ``out`` (what the model's sum calls)."""
        f = self.forces(x, v, t, found)
        if f is not None:
            out += f

    def blocks(self, x, v, t: float, kinds, found) -> FamilyBlocks:
        raise NotImplementedError

    def linearization_vjp(self, x, v, t: float, lam, w, q, dt: float, found):
        """``(gx, gv)``: gradients in x and v of ``lam . (dt f + dt^2 K w + dt D q)``."""
        raise NotImplementedError

    def linearization_jvp(self, x, v, t: float, w, q, dt: float, dx, dv, found):
        """The derivative of ``dt f + dt^2 K w + dt D q`` along ``(dx, dv)``, ``(n, 3)``."""
        raise NotImplementedError

    def symbolic_forces(self, X, V, S, decisions=None):
        """:meth:`forces` as a ``3 x n`` CasADi expression (S: :meth:`parameters`; decisions:
        what the step decided, :meth:`decision_parameters`, for a law that takes them)."""
        raise NotImplementedError

    def symbolic_blocks(self, X, V, S, decisions=None) -> FamilyBlocks:
        """``(K, D)`` blocks as CasADi columns: ``pairs`` ``9 x P``, ``particles`` ``9 x n``,
        ``stencil_blocks`` ``9 k^2 x P`` (row-major; every pair of the family, for small
        systems), given what the step decided (:meth:`decision_parameters`; None: nothing)."""
        raise NotImplementedError

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        """``dt f + dt^2 K W + dt D Q`` as a ``3 x n`` CasADi expression: the family's part
        of a linearized step's right side, written per interaction (no assembled K or D,
        so a transcription of many steps stays small); X, V, W, Q ``3 x n``."""
        raise NotImplementedError(f"{type(self).__name__} has no symbolic step: the "
                                  "transcription cannot write its inverse step")

    def step_jacobian(self, x, v, w, q, times, dt):
        """The Jacobian of :meth:`symbolic_step`'s function at many steps at once:
        ``(particles, blocks)``, ``particles`` ``(P, k)`` the interactions' particles (the
        same at every step) and ``blocks`` ``(steps, P, 4, 3k, 3k)``, the derivatives of
        each interaction's ``3k`` outputs in x, v, w and q of its particles; x, v, w, q are
        ``(steps, n, 3)``, ``times`` the steps' start times.  None: the family adds
        nothing (the hold, which acts through the solve)."""
        raise NotImplementedError(f"{type(self).__name__} has no step Jacobian: the "
                                  "transcription cannot write its inverse step")


class PairInteraction(Interaction):
    """A law of two particles, ``(d = x_j - x_i, dv = v_j - v_i, *params) -> f_i``, lifted
    over pairs: ``+f`` on i, ``-f`` on j.  Subclasses give :meth:`pairs` and
    :meth:`pair_parameters` (per-pair columns) and :meth:`all_pairs` (the symbolic route's
    pairs, and the fixed ones' pattern)."""

    fixed_pairs = True  # pairs(found) is all_pairs() at every state (springs); False: found

    def __init__(self, kernels: dict, n: int, jit: bool | None):
        self.kernels, self.n = kernels, n
        self.mapped = {k: MappedKernel(kernels[k], jit=jit) for k in KERNELS}

    def pairs(self, found) -> tuple[np.ndarray, np.ndarray] | None:
        """The pairs ``(i, j)`` acting now (None if none)."""
        raise NotImplementedError

    def pair_parameters(self, i: np.ndarray, j: np.ndarray, found=None) -> list:
        """The kernels' inputs after ``d, dv`` for the pairs ``(i, j)``, ``(P, k)`` each
        (``found``: what :meth:`~Interaction.find` or the step decided)."""
        raise NotImplementedError

    def symbolic_pair_parameters(self, i: np.ndarray, j: np.ndarray, decisions=None) -> list:
        """:meth:`pair_parameters` as CasADi rows ``k x P`` for the symbolic route."""
        return [ca.DM(np.asarray(a).T) for a in self.pair_parameters(i, j)]

    def all_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def structure(self):
        return (self.all_pairs() if self.fixed_pairs else None), None

    def _inputs(self, x, v, i, j, found):
        return [pair_difference(x, i, j), pair_difference(v, i, j),
                *self.pair_parameters(i, j, found)]

    def forces(self, x, v, t, found):
        ij = self.pairs(found)
        if ij is None:
            return None
        (f,) = self.mapped["force"](*self._inputs(x, v, *ij, found))
        return scatter_pairs(f, *ij, self.n)

    def blocks(self, x, v, t, kinds, found):
        ij = self.pairs(found)
        if ij is None:
            return FamilyBlocks()
        inputs = self._inputs(x, v, *ij, found)
        return FamilyBlocks(*ij, tuple(b for k in kinds for b in self.mapped[k](*inputs)))

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        ij = self.pairs(found)
        if ij is None:
            return None
        vectors = [pair_difference(a, *ij) for a in (-lam, w, q)]
        gd, gdv = self.mapped["vjp"](*self._inputs(x, v, *ij, found), *vectors,
                                     np.full((ij[0].size, 1), dt))
        return -scatter_pairs(gd, *ij, self.n), -scatter_pairs(gdv, *ij, self.n)

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        ij = self.pairs(found)
        if ij is None:
            return None
        vectors = [pair_difference(a, *ij) for a in (w, q)]
        deltas = [pair_difference(a, *ij) for a in (dx, dv)]
        (dg,) = self.mapped["jvp"](*self._inputs(x, v, *ij, found), *vectors,
                                   np.full((ij[0].size, 1), dt), *deltas)
        return scatter_pairs(dg, *ij, self.n)

    def _symbolic(self, kind, X, V, decisions=None):
        i, j = self.all_pairs()
        params = self.symbolic_pair_parameters(i, j, decisions)
        out = self.kernels[kind].map(i.size)(X[:, j] - X[:, i], V[:, j] - V[:, i], *params)
        return i, j, (list(out) if isinstance(out, (list, tuple)) else [out])

    def symbolic_forces(self, X, V, S, decisions=None):
        i, j, (f,) = self._symbolic("force", X, V)
        return ca.mtimes(f, pair_incidence(i, j, self.n))

    def symbolic_blocks(self, X, V, S, decisions=None):
        i, j, blocks = self._symbolic("jac", X, V, decisions)
        return FamilyBlocks(i, j, tuple(blocks))

    def step_jacobian(self, x, v, w, q, times, dt):
        if not self.fixed_pairs:
            raise NotImplementedError(f"{self.name} acts over pairs found per state: the "
                                      "transcription has no fixed pattern for it")
        i, j = self.all_pairs()
        steps, P = x.shape[0], i.size
        inputs = [(a[:, j] - a[:, i]).reshape(-1, 3) for a in (x, v)]
        params = [np.tile(p, (steps, 1)) for p in self.pair_parameters(i, j)]
        deltas = [(a[:, j] - a[:, i]).reshape(-1, 3) for a in (w, q)]
        (jac,) = _kernel(self, "step_jac")(*inputs, *params, *deltas, np.full((steps * P, 1), dt))
        A = jac.reshape(steps, P, 3, 4, 3).transpose(0, 1, 3, 2, 4)  # (steps, P, 4, 3, 3)
        blocks = np.empty((steps, P, 4, 6, 6))
        blocks[..., :3, :3] = blocks[..., 3:, 3:] = -A  # g on i, -g on j; g of x_j - x_i
        blocks[..., :3, 3:] = blocks[..., 3:, :3] = A
        return np.stack([i, j], axis=1), blocks

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        i, j = self.all_pairs()
        params = self.symbolic_pair_parameters(i, j, decisions)
        g = self.kernels["step"].map(i.size)(X[:, j] - X[:, i], V[:, j] - V[:, i], *params,
                                             W[:, j] - W[:, i], Q[:, j] - Q[:, i], dt)
        return ca.mtimes(g, pair_incidence(i, j, self.n))


class ParticleInteraction(Interaction):
    """A law of one particle, ``(x, v, *columns) -> f``, over every particle; its Jacobian
    blocks are diagonal.  Subclasses give :meth:`columns` (the kernels' inputs after
    ``x, v`` at time t, one row per particle; :meth:`columns_at` when they depend on x too)
    and :meth:`parameters`, and :meth:`symbolic_columns` for the symbolic route."""

    def __init__(self, kernels: dict, n: int, jit: bool | None):
        self.kernels, self.n = kernels, n
        self.mapped = {k: MappedKernel(kernels[k], jit=jit) for k in KERNELS}

    def columns(self, t: float) -> list:
        raise NotImplementedError

    def columns_at(self, x, t: float, found) -> list:
        """The kernels' inputs after ``x, v`` at positions x and time t, given ``found``
        (what the family found or decided there): :meth:`columns` here."""
        return self.columns(t)

    def symbolic_columns(self, S, decisions=None) -> list:
        """The kernels' inputs after ``x, v`` from this family's symbolic parameters S (and
        the step's ``decisions``), as columns: one for all particles (repeated by the
        kernel's map) or one per particle."""
        raise NotImplementedError

    def forces(self, x, v, t, found):
        return self.mapped["force"](x, v, *self.columns_at(x, t, found))[0]

    def blocks(self, x, v, t, kinds, found):
        columns = self.columns_at(x, t, found)
        return FamilyBlocks(particles=tuple(b for k in kinds
                                            for b in self.mapped[k](x, v, *columns)))

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        return tuple(self.mapped["vjp"](x, v, *self.columns_at(x, t, found), lam, w, q,
                                        np.full((self.n, 1), dt)))

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        return self.mapped["jvp"](x, v, *self.columns_at(x, t, found), w, q,
                                  np.full((self.n, 1), dt), dx, dv)[0]

    def _symbolic(self, kind, X, V, S, decisions=None):
        n = X.shape[1]
        columns = [c if c.shape[1] == n else ca.repmat(c, 1, n)
                   for c in self.symbolic_columns(S, decisions)]
        out = self.kernels[kind].map(n)(X, V, *columns)
        return list(out) if isinstance(out, (list, tuple)) else [out]

    def symbolic_forces(self, X, V, S, decisions=None):
        return self._symbolic("force", X, V, S, decisions)[0]

    def symbolic_blocks(self, X, V, S, decisions=None):
        return FamilyBlocks(particles=tuple(self._symbolic("jac", X, V, S, decisions)))

    def step_jacobian(self, x, v, w, q, times, dt):
        steps, n = x.shape[:2]
        jac = np.empty((steps, n, 36))
        for k in range(steps):
            (jac[k],) = _kernel(self, "step_jac")(x[k], v[k], *self.columns_at(x[k], times[k], None),
                                        w[k], q[k], np.full((n, 1), dt))
        blocks = jac.reshape(steps, n, 3, 4, 3).transpose(0, 1, 3, 2, 4)
        return np.arange(n)[:, None], blocks

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        n = X.shape[1]
        columns = [c if c.shape[1] == n else ca.repmat(c, 1, n)
                   for c in self.symbolic_columns(S, decisions)]
        return self.kernels["step"].map(n)(X, V, *columns, W, Q, dt)


class StencilInteraction(Interaction):
    """A law of k particles, ``(x, v, *params) -> f`` with x, v and f the ``3k`` stacked
    positions, velocities and forces of a stencil's particles, lifted over fixed stencils
    ``(P, k)`` (a hinge's four particles); its Jacobian blocks are the whole ``3k x 3k``
    matrices.  Subclasses give :meth:`stencil_parameters` (per-stencil rows)."""

    def __init__(self, kernels: dict, stencils: np.ndarray, n: int, jit: bool | None):
        self.kernels, self.n = kernels, n
        self.stencils = np.asarray(stencils, np.intp)
        self.stencils.flags.writeable = False
        self.mapped = {k: MappedKernel(kernels[k], jit=jit) for k in KERNELS}

    def stencil_parameters(self) -> list:
        """The kernels' inputs after ``x, v``, ``(P, m)`` each."""
        raise NotImplementedError

    def structure(self):
        return None, self.stencils

    def _inputs(self, x, v):
        return [stencil_values(x, self.stencils), stencil_values(v, self.stencils),
                *self.stencil_parameters()]

    def forces(self, x, v, t, found):
        (f,) = self.mapped["force"](*self._inputs(x, v))
        return scatter_stencils(f, self.stencils, self.n)

    def blocks(self, x, v, t, kinds, found):
        inputs = self._inputs(x, v)
        return FamilyBlocks(stencil=self.stencils, stencil_blocks=tuple(
            b for k in kinds for b in self.mapped[k](*inputs)))

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        vectors = [stencil_values(a, self.stencils) for a in (lam, w, q)]
        gx, gv = self.mapped["vjp"](*self._inputs(x, v), *vectors,
                                    np.full((self.stencils.shape[0], 1), dt))
        return (scatter_stencils(gx, self.stencils, self.n),
                scatter_stencils(gv, self.stencils, self.n))

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        vectors = [stencil_values(a, self.stencils) for a in (w, q)]
        deltas = [stencil_values(a, self.stencils) for a in (dx, dv)]
        (dg,) = self.mapped["jvp"](*self._inputs(x, v), *vectors,
                                   np.full((self.stencils.shape[0], 1), dt), *deltas)
        return scatter_stencils(dg, self.stencils, self.n)

    def _symbolic(self, kind, X, V):
        P, k = self.stencils.shape
        columns = self.stencils.ravel().tolist()
        stacked = [ca.reshape(A[:, columns], 3 * k, P) for A in (X, V)]
        params = [ca.DM(np.asarray(a).T) for a in self.stencil_parameters()]
        out = self.kernels[kind].map(P)(*stacked, *params)
        return list(out) if isinstance(out, (list, tuple)) else [out]

    def symbolic_forces(self, X, V, S, decisions=None):
        (f,) = self._symbolic("force", X, V)
        return ca.mtimes(ca.reshape(f, 3, self.stencils.size),
                         stencil_incidence(self.stencils, self.n))

    def symbolic_blocks(self, X, V, S, decisions=None):
        return FamilyBlocks(stencil=self.stencils,
                            stencil_blocks=tuple(self._symbolic("jac", X, V)))

    def step_jacobian(self, x, v, w, q, times, dt):
        steps = x.shape[0]
        P, k = self.stencils.shape
        stacked = [a[:, self.stencils].reshape(steps * P, 3 * k) for a in (x, v, w, q)]
        params = [np.tile(p, (steps, 1)) for p in self.stencil_parameters()]
        (jac,) = _kernel(self, "step_jac")(*stacked[:2], *params, *stacked[2:],
                                 np.full((steps * P, 1), dt))
        blocks = jac.reshape(steps, P, 3 * k, 4, 3 * k).transpose(0, 1, 3, 2, 4)
        return self.stencils, blocks

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        P, k = self.stencils.shape
        columns = self.stencils.ravel().tolist()
        stacked = [ca.reshape(A[:, columns], 3 * k, P) for A in (X, V, W, Q)]
        params = [ca.DM(np.asarray(a).T) for a in self.stencil_parameters()]
        g = self.kernels["step"].map(P)(*stacked[:2], *params, *stacked[2:], dt)
        return ca.mtimes(ca.reshape(g, 3, self.stencils.size),
                         stencil_incidence(self.stencils, self.n))


def _kernel(family, name: str) -> MappedKernel:
    """The family's mapped kernel ``name`` (the transcription's ``step_jac``), made (and
    compiled) at its first use."""
    made = family.__dict__.setdefault("_transcription_kernels", {})
    if name not in made:
        made[name] = MappedKernel(family.kernels[name],
                                  jit=getattr(family.mapped.get("force"), "jit", None))
    return made[name]
