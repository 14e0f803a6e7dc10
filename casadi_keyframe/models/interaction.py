r"""An interaction family: one force law acting over many interactions of a particle system
(the springs, one collider's contacts, self-contact, gravity and drag), as a unit.

A family gives, at positions and velocities ``x, v`` (``(n, 3)``) at time t, everything an
implicit step and its exact derivatives need, and the same in CasADi for the reference route:

* :meth:`~Interaction.forces`: its force on every particle, ``(n, 3)``;
* :meth:`~Interaction.blocks`: its Jacobians as 3x3 blocks per pair and per particle, for
  the kernels named (``"jac"``: the step's stiffness K and damping D; ``"df_dx"``: the full
  position derivative J);
* :meth:`~Interaction.linearization_vjp` and :meth:`~Interaction.linearization_jvp`: the
  second derivatives the exact adjoint and tangent of a linearized step need, contracted per
  interaction (see :func:`~casadi_keyframe.kernels.interaction_kernels`);
* :meth:`~Interaction.symbolic_forces` and :meth:`~Interaction.symbolic_blocks`: the same
  force and blocks as CasADi expressions of ``3 x n`` matrices X, V and the family's scene
  parameters (:meth:`~Interaction.parameters`).

What a family acts over may depend on the state (self-contact's pairs): :meth:`find` gives it
once per state and every other method takes it back as ``found``, so one step searches once.

Two shapes of family cover the cloth's laws, after jax-md's split of a per-pair law and its
lifting over pairs: a :class:`PairInteraction` lifts a kernel of ``d = x_j - x_i`` over pairs
(force ``+f`` on i and ``-f`` on j, so it sums to zero), a :class:`ParticleInteraction` a
kernel of one particle's ``x, v`` over every particle.  A new force law is one file with one
such class; the model lists it once.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..kernels import MappedKernel, pair_difference, pair_incidence, scatter_pairs

KERNELS = ("force", "jac", "df_dx", "vjp", "jvp")  # every family's, see interaction_kernels
OUTPUTS = {"jac": 2, "df_dx": 1}  # blocks per kernel: (K, D) and J


@dataclass(frozen=True)
class FamilyBlocks:
    """One family's Jacobian blocks for the kernels asked (in order, ``(K, D)`` for "jac",
    ``J`` for "df_dx"): ``pairs`` ``(P, 9)`` arrays over the pairs ``(i, j)`` and
    ``particles`` ``(n, 9)`` arrays on the diagonal, either None when the family has none."""

    i: np.ndarray | None = None
    j: np.ndarray | None = None
    pairs: tuple | None = None
    particles: tuple | None = None


class Interaction:
    """Base of a family (module docstring); subclasses give the numeric and symbolic forms.

    ``name`` says what the family is; ``role`` what kind of force it is: "internal" (sums to
    zero: springs), "external" (gravity, drag) or "contact" (colliders, self-contact)."""

    name = "interaction"
    role = "external"

    def find(self, x: np.ndarray):
        """What the family acts over at positions x beyond its fixed structure (None: fixed)."""
        return None

    def parameters(self, t: float) -> np.ndarray:
        """The family's time-dependent inputs at time t as one flat vector (the symbolic S)."""
        return np.zeros(0)

    def decisions(self, found) -> np.ndarray:
        """What a step decided for this family (``found``) as the flat inputs its symbolic
        Jacobian blocks take (none here: see the springs' taut flags)."""
        return np.zeros(0)

    def decision_size(self) -> int:
        return self.decisions(None).size

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

    def symbolic_forces(self, X, V, S):
        """:meth:`forces` as a ``3 x n`` CasADi expression (S: :meth:`parameters`)."""
        raise NotImplementedError

    def symbolic_blocks(self, X, V, S, decisions=None) -> FamilyBlocks:
        """``(K, D)`` blocks as CasADi columns: ``pairs`` ``9 x P``, ``particles`` ``9 x n``
        (row-major blocks; every pair of the family, for small systems), given what the step
        decided (:meth:`decisions`; None: nothing)."""
        raise NotImplementedError


class PairInteraction(Interaction):
    """A law of two particles, ``(d = x_j - x_i, dv = v_j - v_i, *params) -> f_i``, lifted
    over pairs: ``+f`` on i, ``-f`` on j.  Subclasses give :meth:`pairs` and
    :meth:`pair_parameters` (per-pair columns) and :meth:`all_pairs` (the symbolic route's
    pairs)."""

    fixed_pairs = True  # the same pairs at every state (springs); False: found per state

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

    def symbolic_forces(self, X, V, S):
        i, j, (f,) = self._symbolic("force", X, V)
        return ca.mtimes(f, pair_incidence(i, j, self.n))

    def symbolic_blocks(self, X, V, S, decisions=None):
        i, j, blocks = self._symbolic("jac", X, V, decisions)
        return FamilyBlocks(i, j, tuple(blocks))


class ParticleInteraction(Interaction):
    """A law of one particle, ``(x, v, *columns) -> f``, over every particle; its Jacobian
    blocks are diagonal.  Subclasses give :meth:`columns` (the kernels' inputs after
    ``x, v`` at time t, one row per particle) and :meth:`parameters`, and
    :meth:`split_parameters` for the symbolic route."""

    def __init__(self, kernels: dict, n: int, jit: bool | None):
        self.kernels, self.n = kernels, n
        self.mapped = {k: MappedKernel(kernels[k], jit=jit) for k in KERNELS}

    def columns(self, t: float) -> list:
        raise NotImplementedError

    def symbolic_columns(self, S) -> list:
        """The kernels' inputs after ``x, v`` from this family's symbolic parameters S,
        as columns (each repeated over the particles by the kernel's map)."""
        raise NotImplementedError

    def forces(self, x, v, t, found):
        return self.mapped["force"](x, v, *self.columns(t))[0]

    def blocks(self, x, v, t, kinds, found):
        columns = self.columns(t)
        return FamilyBlocks(particles=tuple(b for k in kinds
                                            for b in self.mapped[k](x, v, *columns)))

    def linearization_vjp(self, x, v, t, lam, w, q, dt, found):
        return tuple(self.mapped["vjp"](x, v, *self.columns(t), lam, w, q,
                                        np.full((self.n, 1), dt)))

    def linearization_jvp(self, x, v, t, w, q, dt, dx, dv, found):
        return self.mapped["jvp"](x, v, *self.columns(t), w, q, np.full((self.n, 1), dt),
                                  dx, dv)[0]

    def _symbolic(self, kind, X, V, S):
        n = X.shape[1]
        columns = [ca.repmat(c, 1, n) for c in self.symbolic_columns(S)]
        out = self.kernels[kind].map(n)(X, V, *columns)
        return list(out) if isinstance(out, (list, tuple)) else [out]

    def symbolic_forces(self, X, V, S):
        return self._symbolic("force", X, V, S)[0]

    def symbolic_blocks(self, X, V, S, decisions=None):
        return FamilyBlocks(particles=tuple(self._symbolic("jac", X, V, S)))
