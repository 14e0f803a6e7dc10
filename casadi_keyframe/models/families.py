r"""A model whose forces are a list of interaction families (:mod:`.interaction`), each method
one loop over the list: forces, Jacobian blocks gathered into one fixed pattern, the
linearization's derivative contractions, their symbolic forms, and what a step decides for
each family (decided, solved, revised, carried, and given to the symbolic step) including the
set the step's hold holds.  Nothing here knows a particular law: a family's kind shows only
in what it gives (its fixed pairs and stencils, whether it holds).
"""
from __future__ import annotations

import copy
import functools

import casadi as ca
import numpy as np

from .base import BlockJacobians, StepHold
from .blocks import BlockPattern, Blocks, pair_block_matrices
from .interaction import OUTPUTS, Interaction, StepSpan


def check_families(families) -> tuple:
    """``families`` as a tuple, each an :class:`~.interaction.Interaction` and at most one
    holding (ValueError otherwise)."""
    families = tuple(families)
    for family in families:
        if not isinstance(family, Interaction):
            raise ValueError(f"families must be Interaction objects, got {family!r}")
    if sum(f.holds for f in families) > 1:
        raise ValueError("a model takes one family that holds (one BodyHold over all its "
                         f"bodies), got {[f.name for f in families if f.holds]}")
    return families


class FamilyModel(BlockJacobians, StepHold):
    """The sums over ``families`` (set by the model, with ``n``, ``masses`` and
    ``free_mask()``) for a model of ``(n, 3)`` states; the step matrix's fixed pattern is
    every family's fixed pairs and stencils (:meth:`~.interaction.Interaction.structure`),
    pairs found per state (self-contact) following the fixed ones."""

    families: tuple

    def family(self, name: str) -> Interaction:
        """The first interaction family named ``name`` (e.g. "self-contact")."""
        for family in self.families:
            if family.name == name:
                return family
        raise KeyError(f"this model has no {name!r} family; it has "
                       f"{[f.name for f in self.families]}")

    def restricted(self, keep) -> "FamilyModel":
        """A copy of this model with only the families ``keep(family)`` accepts (the same
        family objects; what is derived from the families is derived again): for a route
        that writes part of the step itself and leaves the rest to ``simulate``."""
        families = tuple(f for f in self.families if keep(f))
        if len(families) == len(self.families):
            return self
        out = copy.copy(self)
        state = vars(out)
        for name in [k for k, v in vars(FamilyModel).items()
                     if isinstance(v, functools.cached_property)]:
            state.pop(name, None)
        state["families"] = check_families(families)
        return out

    # -- structure -----------------------------------------------------------------------
    @functools.cached_property
    def fixed_structure(self) -> tuple:
        """``(i, j, stencils)``: every family's fixed pairs, family after family, and its
        stencils (one ``(P, k)`` array per stencil family)."""
        pairs, stencils = [], []
        for family in self.families:
            ij, stencil = family.structure()
            if ij is not None:
                pairs.append(ij)
            if stencil is not None:
                stencils.append(stencil)
        i = np.concatenate([p[0] for p in pairs]) if pairs else np.zeros(0, np.intp)
        j = np.concatenate([p[1] for p in pairs]) if pairs else np.zeros(0, np.intp)
        return i, j, tuple(stencils)

    @functools.cached_property
    def block_pattern(self) -> BlockPattern:
        """The fixed structure's :class:`~.blocks.BlockPattern` over all components."""
        i, j, stencils = self.fixed_structure
        return BlockPattern(i, j, self.n, stencils=stencils)

    @functools.cached_property
    def step_pattern(self) -> BlockPattern:
        """The fixed structure's pattern restricted to the free components: the structure of
        an implicit step matrix's free block without found pairs."""
        i, j, stencils = self.fixed_structure
        return BlockPattern(i, j, self.n, self.free_mask(), stencils=stencils)

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
                        with_df_dx: bool = False, interactions=None,
                        reuse: dict | None = None) -> tuple[Blocks, ...]:
        """``(K, D[, J])`` (see :meth:`jacobians`) as :class:`~.blocks.Blocks` over the
        fixed pairs followed by the pairs found at x (self-contact), and the stencils.
        ``reuse``: a dict the caller keeps, in which each family's blocks are remembered
        and given again for the same x, v and t (the same arrays) and the same decision (a
        step solved again after a revision of another family's)."""
        kinds = ("jac", "df_dx") if with_df_dx else ("jac",)
        return self._blocks(x, v, t, interactions, kinds, reuse)

    def force_jacobian_blocks(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
                              interactions=None) -> Blocks:
        """The full ``df/dx`` alone as :class:`~.blocks.Blocks` (what the swapped adjoint
        needs when the step matrix's factor is already at hand)."""
        return self._blocks(x, v, t, interactions, ("df_dx",))[0]

    def _blocks(self, x, v, t, interactions, kinds, reuse=None) -> tuple[Blocks, ...]:
        """The blocks of kernels ``kinds`` ("jac": K and D, "df_dx": J) of every family."""
        width = sum(OUTPUTS[k] for k in kinds)
        fixed, found_pairs, stencils = [], [], []  # (i, j, blocks) of pair families
        particles = [np.zeros((self.n, 9)) for _ in range(width)]
        for k, (family, found) in enumerate(zip(self.families, self._found(x, interactions))):
            part = _remembered(reuse, (k, kinds), (x, v, t, found),
                               lambda: family.blocks(self._check_state(x, "x"),
                                                     self._check_state(v, "v"), t, kinds, found))
            if part.pairs is not None:
                group = fixed if family.fixed_pairs else found_pairs
                group.append((part.i, part.j, part.pairs))
            if part.stencil is not None:
                stencils.append((part.stencil, part.stencil_blocks))
            for acc, b in zip(particles, part.particles or ()):
                if b is not None:
                    acc += b
        groups = fixed + found_pairs
        if len(groups) == 1:
            i, j, pairs = groups[0]
        else:
            i = np.concatenate([g[0] for g in groups] or [np.zeros(0, np.intp)])
            j = np.concatenate([g[1] for g in groups] or [np.zeros(0, np.intp)])
            pairs = [np.vstack([g[2][k] for g in groups] or [np.zeros((0, 9))])
                     for k in range(width)]
        return tuple(Blocks(i, j, p, q, tuple((s, b[k]) for s, b in stencils))
                     for k, (p, q) in enumerate(zip(pairs, particles)))

    def jacobians(self, x: np.ndarray, v: np.ndarray, t: float = 0.0, with_df_dx: bool = False,
                  interactions=None):
        """``(K, D)`` as 3n x 3n CSC matrices at time t, both symmetric, ``-K`` and ``-D``
        positive semi-definite; with ``with_df_dx`` also the full ``df/dx`` (not symmetric).

        ``D = df/dv``.  K is the stiffness the implicit step uses: ``df/dx`` at zero velocity
        (damping's position derivative omitted, as in Baraff-Witkin) without each law's
        destabilising part (compressed springs' transverse term, contact surfaces'
        curvature, a hinge's angle curvature: :func:`.springs.spring_law`,
        :func:`.contact.penalty.penalty_law`, :func:`.bending.hinge_law`).  The adjoints of full
        backward Euler (exact and swapped) need the true ``df/dx``, damping's part included.
        """
        blocks = self.jacobian_blocks(x, v, t, with_df_dx, interactions)
        S = self.block_pattern.i.size
        out = [self.block_pattern.matrix(b.pairs[:S], b.particles, b.stencil_blocks)
               for b in blocks]
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
        ``dt f + dt^2 K w + dt D q`` at time t along ``(dx, dv)``, ``(n, 3)``."""
        out = np.zeros((self.n, 3))
        for family, found in zip(self.families, self._found(x, interactions)):
            dg = family.linearization_jvp(x, v, t, w, q, dt, dx, dv, found)
            if dg is not None:
                out += dg
        return out

    # -- what a step decides -------------------------------------------------------------
    def _span(self, x, v, t, dt, x1=None) -> StepSpan:
        whole = self.free_mask().reshape(self.n, 3).all(axis=1)
        return StepSpan(x, v, t, dt, whole, x1)

    def step_decisions(self, x, v, t: float, dt: float, carried=None) -> tuple:
        """Each family's ``found`` for a step from (x, v) at t (its decision), after a step
        that left ``carried`` (:meth:`carried_decisions`; None: a run's start)."""
        step = self._span(x, v, t, dt)
        carried = (None,) * len(self.families) if carried is None else carried
        return tuple(f.decide(step, c) for f, c in zip(self.families, carried))

    def solved_decisions(self, decisions, residual) -> tuple:
        """``decisions`` given the solved step's residual ``A dv - b`` (the hold's impulses)."""
        return tuple(f.solved(d, residual) for f, d in zip(self.families, decisions))

    def revised_decisions(self, decisions, x, v, t: float, dt: float, x1):
        """``(decisions, again)`` after the step from (x, v) at t ended at x1: revised where
        the end shows the step chose wrong (particles the hold should have held, springs it
        should have taken taut), ``again`` if it must be solved again with them; else what
        the step defers to the next (:meth:`~.interaction.Interaction.settle`)."""
        end = self._span(x, v, t, dt, x1)
        stopped = any([f.stops(d, end) for f, d in zip(self.families, decisions)])
        revised = [f.revise(d, end, stopped) for f, d in zip(self.families, decisions)]
        if any(r is not None for r in revised):
            return tuple(d if r is None else r for d, r in zip(decisions, revised)), True
        return tuple(f.settle(d, end, stopped) for f, d in zip(self.families, decisions)), False

    def carried_decisions(self, decisions):
        """What the next step takes from a step's ``decisions`` (None: nothing)."""
        carried = tuple(f.carry(d) for f, d in zip(self.families, decisions))
        return None if all(c is None for c in carried) else carried

    def decision_parameters(self, decisions=None, t: float = 0.0, dt: float = 1.0) -> np.ndarray:
        """A step's ``decisions`` (None: nothing beyond the state) as the flat inputs
        :meth:`symbolic_jacobians` and :meth:`symbolic_hold` take, family after family."""
        decisions = (None,) * len(self.families) if decisions is None else decisions
        return np.concatenate([f.decision_parameters(d, t, dt)
                               for f, d in zip(self.families, decisions)])

    # -- the hold --------------------------------------------------------------------------
    @functools.cached_property
    def _hold_index(self):
        return next((k for k, f in enumerate(self.families) if f.holds), None)

    @property
    def holding(self) -> bool:
        return self._hold_index is not None

    def held(self, decisions):
        return None if self._hold_index is None else decisions[self._hold_index]

    def hold_vjp(self, x, v, t: float, dt: float, held, lam, q, nu):
        return self.families[self._hold_index].vjp(x, v, t, dt, held, lam, q, nu)

    def hold_jvp(self, x, v, t: float, dt: float, held, q, dx, dv):
        return self.families[self._hold_index].jvp(x, v, t, dt, held, q, dx, dv)

    def symbolic_hold(self, X, V, decided, dt):
        if self._hold_index is None:
            return None
        at = sum(f.decision_size() for f in self.families[:self._hold_index])
        hold = self.families[self._hold_index]
        return hold.symbolic_held(X, V, decided[at:at + hold.decision_size()], dt)

    # -- symbolic ------------------------------------------------------------------------
    def scene_parameters(self, t: float) -> np.ndarray:
        """Every family's time-dependent inputs at time t as one flat vector (the symbolic S:
        the bodies' geometry)."""
        return np.concatenate([f.parameters(t) for f in self.families])

    def scene_parts(self, S, decisions=None):
        """Each family with its slices of the scene parameters S (default: those at t = 0)
        and of the step's ``decisions`` (None: nothing, or a family that decides nothing)."""
        S = ca.DM(self.scene_parameters(0.0)) if S is None else S
        at = decided = 0
        for family in self.families:
            size, size_d = family.parameters(0.0).size, family.decision_size()
            mine = None if decisions is None or not size_d else decisions[decided:decided + size_d]
            yield family, S[at:at + size], mine
            at, decided = at + size, decided + size_d

    def symbolic_forces(self, X, V, S=None, decisions=None):
        """:meth:`forces` as a CasADi expression; X, V are ``3 x n`` (column k = particle k),
        S the :meth:`scene_parameters` (default: those at t = 0) and ``decisions`` the
        step's (:meth:`decision_parameters`; None: nothing).  Pair families act over every
        pair they might (self-contact: all unjoined pairs): for small systems."""
        out = 0
        for family, part, mine in self.scene_parts(S, decisions):
            out += family.symbolic_forces(X, V, part, mine)
        return out

    def step_jacobians(self, x, v, w, q, times, dt) -> list:
        """Each family's :meth:`~.interaction.Interaction.step_jacobian` at many steps at
        once (x, v, w, q ``(steps, n, 3)``): ``[(particles, blocks), ...]``, the families
        that add nothing left out."""
        out = []
        for family in self.families:
            found = family.step_jacobian(x, v, w, q, times, dt)
            if found is not None:
                out.append(found)
        return out

    def symbolic_step(self, X, V, W, Q, S, dt, decisions=None):
        """``dt f + dt^2 K W + dt D Q`` (``3 x n``, the right side of a linearized step less
        its control) summed over the families, each written per interaction; S the
        :meth:`scene_parameters` at the step's time and ``decisions`` the step's."""
        out = 0
        for family, part, mine in self.scene_parts(S, decisions):
            out += family.symbolic_step(X, V, W, Q, part, dt, mine)
        return out

    def symbolic_jacobians(self, X, V, S=None, decisions=None):
        """:meth:`jacobians` as sparse CasADi expressions ``(K, D)``, assembled from the same
        kernels and patterns (so K is the step's clamped stiffness, not ``df/dx``), given the
        step's ``decisions`` (:meth:`decision_parameters`; None: nothing)."""
        zeros = ca.SX.zeros(9, self.n)
        particles, fixed, stencils, extra = [zeros, zeros], ([], []), ([], []), []
        for family, part, mine in self.scene_parts(S, decisions):
            blocks = family.symbolic_blocks(X, V, part, mine)
            for k, b in enumerate(blocks.particles or ()):
                if b is not None:
                    particles[k] = particles[k] + b
            for k, b in enumerate(blocks.stencil_blocks or ()):
                stencils[k].append(ca.vec(b))
            if blocks.pairs is not None:
                if family.fixed_pairs:
                    for k in range(2):
                        fixed[k].append(blocks.pairs[k])
                else:
                    extra.append(blocks)
        K, D = (_symbolic_csc(self.block_pattern, ca.vertcat(
            ca.vec(ca.horzcat(*fixed[k]) if fixed[k] else ca.SX(9, 0)), ca.vec(particles[k]),
            *stencils[k])) for k in range(2))
        for blocks in extra:
            pattern = BlockPattern(blocks.i, blocks.j, self.n, particle_blocks=False)
            K += _symbolic_csc(pattern, ca.vec(blocks.pairs[0]))
            D += _symbolic_csc(pattern, ca.vec(blocks.pairs[1]))
        return K, D

    def _check_state(self, a, name: str) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.shape != (self.n, 3):
            raise ValueError(f"{name} must have shape ({self.n}, 3), got {a.shape}")
        return a


def _remembered(memory: dict | None, key, inputs: tuple, compute):
    """``compute()``, or what it gave for the same ``inputs`` (the same objects; t equal)
    when ``memory`` (a dict) remembers it under ``key``."""
    if memory is None:
        return compute()
    kept = memory.get(key)
    if kept is not None and kept[0][2] == inputs[2] and all(
            a is b for k, (a, b) in enumerate(zip(kept[0], inputs)) if k != 2):
        return kept[1]
    value = compute()
    memory[key] = (inputs, value)
    return value


def _symbolic_csc(pattern: BlockPattern, blocks) -> ca.SX:
    """The sparse SX matrix of a :class:`BlockPattern` filled with ``blocks`` (a column: the
    row-major blocks one after another, as the numeric route's data)."""
    size = pattern.size
    sparsity = ca.Sparsity(size, size, pattern.indptr.tolist(), pattern.indices.tolist())
    return ca.SX(sparsity, ca.mtimes(ca.DM(pattern.gather.tocsc()), blocks))
