r"""The declared contract of a particle system (:class:`Model`) and its named capabilities.

A model is immutable: it is built complete (forces, constraints, kernels) and never changes,
so everything derived from it (a step pattern, a compiled kernel) stays valid.  What a state
needs is computed per call or passed in (``interactions``).  Integrators ask a model only
for what these classes declare; an integrator that needs a capability says so
(:attr:`~casadi_keyframe.integrators.base.Integrator.requires`) and refuses a model without it.

States are ``(n, dim)`` arrays of positions ``x`` and velocities ``v``; the flat ``n * dim``
ordering is ``x.ravel()``.  Symbolic forms take ``dim x n`` CasADi matrices (column k is
particle k) and the scene parameters S (:meth:`Model.scene_parameters`).

Capabilities:

* :class:`ForceDerivatives`: transposed and forward Jacobian products of the forces, for
  explicit schemes (a flock under symplectic Euler);
* :class:`ForceJacobians`: the force Jacobians and the linearization's second-derivative
  contractions, for implicit schemes (cloth);
* :class:`BlockJacobians`: the same Jacobians as 3x3 blocks and a fixed step pattern, so a
  sparse Cholesky analyses a step matrix once;
* :class:`StepHold`: particles the implicit step holds on bodies (prescribed normal
  velocities: the hold) and the derivatives of their normals and targets;
* :class:`PhysicalReport`: whether frames stay physical (stretch, penetration);
* :class:`Surface`: a rest mesh, for rendering and export.
"""
from __future__ import annotations

import abc

import casadi as ca
import numpy as np

from ..state import check_state


class Model(abc.ABC):
    """A system of ``n`` particles of ``masses`` (kg) in ``dim`` dimensions.

    Members every model gives (``colliders``, the bodies it touches, defaults to none):

    * ``forces(x, v, t, interactions)``: the total force, ``(n, dim)`` N;
    * ``symbolic_forces(X, V, S)``: the same as a CasADi expression (all interactions);
    * ``interactions(x)``: what the forces at x act over beyond fixed structure (a flock's
      neighbour pairs, a cloth's self-contact pairs), found once per state and passed on;
    * ``scene_parameters(t)``: the time-dependent inputs S of the symbolic forces;
    * ``free_mask()``, ``prescribed_velocity(x, t, dt)``, ``constraint_targets(t)`` and
      ``prescribed_velocity_symbolic(X, targets, dt)``: components held to a prescribed
      velocity (pinned, attached) and their velocity at the end of a step;
    * ``check_state(x, v, step)``: raises :class:`~casadi_keyframe.state.SimulationError`
      if a step's end state has failed (non-finite, or the model's own blow-up test).
    """

    n: int
    dim: int
    masses: np.ndarray
    colliders: tuple = ()  # the analytic bodies the system touches

    @abc.abstractmethod
    def forces(self, x: np.ndarray, v: np.ndarray, t: float = 0.0,
               interactions=None) -> np.ndarray:
        """The total force ``(n, dim)`` at time t (over ``interactions``, default those of x)."""

    @abc.abstractmethod
    def symbolic_forces(self, X, V, S=None):
        """:meth:`forces` as a CasADi expression of ``dim x n`` matrices."""

    def interactions(self, x: np.ndarray):
        """What the forces at positions x act over beyond fixed structure (None: nothing)."""
        return None

    def scene_parameters(self, t: float) -> np.ndarray:
        """The time-dependent inputs S of :meth:`symbolic_forces` at time t (none here)."""
        return np.zeros(0)

    def free_mask(self) -> np.ndarray:
        """Flat bool mask over the ``n * dim`` components: False where prescribed."""
        return np.ones(self.n * self.dim, bool)

    def prescribed_particles(self) -> np.ndarray:
        """Indices of the particles with a prescribed component (pinned, attached)."""
        return np.flatnonzero(~self.free_mask().reshape(self.n, self.dim).all(axis=1))

    def prescribed_velocity(self, x: np.ndarray, t: float, dt: float) -> np.ndarray:
        """``(n, dim)`` velocities of the prescribed components at the end of the step from
        t (zero for free ones, unused)."""
        return np.zeros((self.n, self.dim))

    def constraint_targets(self, t: float) -> np.ndarray:
        """The flat inputs of :meth:`prescribed_velocity_symbolic` for a step ending at t."""
        return np.zeros(0)

    def prescribed_velocity_symbolic(self, X, targets, dt):
        """:meth:`prescribed_velocity` in CasADi (``dim x n``)."""
        return ca.SX.zeros(self.dim, self.n)

    def check_state(self, x: np.ndarray, v: np.ndarray, step: int) -> None:
        """Raise SimulationError if the state at ``step`` is non-finite or beyond bounds."""
        check_state(x, v, step)


class ForceDerivatives(abc.ABC):
    """Jacobian products of the forces over a state's interactions (explicit schemes)."""

    @abc.abstractmethod
    def forces_vjp(self, x, v, t: float, interactions, mu):
        """``((df/dx)^T mu, (df/dv)^T mu)`` at (x, v), each ``(n, dim)``."""

    @abc.abstractmethod
    def forces_jvp(self, x, v, t: float, interactions, dx, dv):
        """``(df/dx) dx + (df/dv) dv`` at (x, v), ``(n, dim)``."""


class ForceJacobians(abc.ABC):
    """What an implicit step and its exact derivatives need of the forces.

    ``K`` is the stiffness the step uses (``df/dx`` at zero velocity with the destabilising
    parts clamped, symmetric, ``-K`` positive semi-definite), ``D = df/dv`` (symmetric,
    ``-D`` positive semi-definite) and ``J`` the full ``df/dx`` (damping's position
    derivative included, not symmetric)."""

    @abc.abstractmethod
    def jacobians(self, x, v, t: float = 0.0, with_df_dx: bool = False, interactions=None):
        """``(K, D)`` (and ``J`` with ``with_df_dx``) as sparse ``n dim x n dim`` matrices."""

    @abc.abstractmethod
    def linearization_vjp(self, x, v, t: float, lam, w, q, dt: float, interactions=None):
        """``(gx, gv)``: the gradients in x and v of ``lam . (dt f + dt^2 K w + dt D q)``."""

    @abc.abstractmethod
    def linearization_jvp(self, x, v, t: float, w, q, dt: float, dx, dv, interactions=None):
        """The derivative of ``dt f + dt^2 K w + dt D q`` along ``(dx, dv)``."""

    @abc.abstractmethod
    def symbolic_jacobians(self, X, V, S=None, decisions=None):
        """``(K, D)`` as sparse CasADi expressions (the same K as :meth:`jacobians`, given
        the step's ``decisions`` as :meth:`decision_parameters`)."""

    # what a step decides beyond the state (each family's ``found``: the springs a step
    # takes taut, the particles its hold holds), revised within the step and carried on
    def step_decisions(self, x, v, t: float, dt: float, carried=None):
        """What a step from (x, v) at t decides at its start, after a step that left
        ``carried`` (:meth:`carried_decisions`, None at a run's start): here, what the
        forces at x act over (:meth:`Model.interactions`)."""
        return self.interactions(x)

    def solved_decisions(self, decisions, residual):
        """``decisions`` given the solved step's residual ``A dv - b`` (flat)."""
        return decisions

    def revised_decisions(self, decisions, x, v, t: float, dt: float, x1):
        """``(decisions, again)`` after the step from (x, v) at t ended at x1: revised, with
        ``again`` True, when the end shows it chose wrong and the step must be solved again;
        else what the step stands by (here, always ``decisions`` unchanged)."""
        return decisions, False

    def carried_decisions(self, decisions):
        """What the next step takes from a step's ``decisions`` (None: nothing)."""
        return None

    def decision_parameters(self, decisions=None, t: float = 0.0, dt: float = 1.0) -> np.ndarray:
        """A step's ``decisions`` (None: nothing beyond the state) as the flat inputs of
        :meth:`symbolic_jacobians` (none here)."""
        return np.zeros(0)


class BlockJacobians(ForceJacobians):
    """:class:`ForceJacobians` also given as 3x3 blocks (:class:`~.blocks.Blocks`) over fixed
    pairs followed by the state's extra pairs, and fixed stencils, with the fixed structure's
    pattern restricted to the free components (:attr:`step_pattern`), so each step matrix is
    gathered into one pattern."""

    @abc.abstractmethod
    def jacobian_blocks(self, x, v, t: float = 0.0, with_df_dx: bool = False,
                        interactions=None, reuse: dict | None = None) -> tuple:
        """``(K, D[, J])`` as :class:`~.blocks.Blocks` (``reuse``: a dict the caller keeps
        to have blocks computed before for the same state and decisions given again)."""

    @abc.abstractmethod
    def force_jacobian_blocks(self, x, v, t: float = 0.0, interactions=None):
        """``J`` alone as :class:`~.blocks.Blocks`."""

    @property
    @abc.abstractmethod
    def step_pattern(self):
        """The fixed structure's :class:`~.blocks.BlockPattern` over the free components."""


class StepHold(abc.ABC):
    """Particles an implicit step holds on bodies by prescribing their velocity along the
    body's normal (the hold, :mod:`~.contact.hold`): the held set among a step's decisions, the
    derivative contractions of its normals and targets for the exact adjoint and tangent,
    and the same in CasADi."""

    @property
    @abc.abstractmethod
    def holding(self) -> bool:
        """Whether the model's steps may hold particles at all."""

    @abc.abstractmethod
    def held(self, decisions):
        """The :class:`~.contact.held_set.HeldSet` among a step's ``decisions`` (None: nothing
        held)."""

    @abc.abstractmethod
    def hold_vjp(self, x, v, t: float, dt: float, held, lam, q, nu):
        """``(gx, gv)``: gradients of ``sum_k -lam_k . n_k (n_k . q_k) + nu_k . z_k``."""

    @abc.abstractmethod
    def hold_jvp(self, x, v, t: float, dt: float, held, q, dx, dv):
        """The derivative of ``-n (n . q) + nbar (nbar . z)`` along ``(dx, dv)``."""

    @abc.abstractmethod
    def symbolic_hold(self, X, V, decided, dt):
        """``(normals 3 x n, targets 1 x n)`` of the held particles (zero elsewhere), the
        decisions ``decided`` as :meth:`~ForceJacobians.decision_parameters` gives them;
        None for a model that holds nothing."""


class PhysicalReport(abc.ABC):
    """Whether a motion stays physical."""

    @abc.abstractmethod
    def max_stretch(self, x: np.ndarray) -> float:
        """The largest spring length over rest length at positions ``x`` (1 at rest)."""

    @abc.abstractmethod
    def physical_report(self, x: np.ndarray, dt: float) -> dict:
        """For frames ``x`` (``(frames, n, dim)``, ``dt`` apart): the largest spring stretch
        and the deepest penetration of a body, each with its frame."""


class Surface(abc.ABC):
    """A rest mesh: ``rest_positions`` ``(n, 3)`` and triangle ``faces`` ``(m, 3)``."""

    rest_positions: np.ndarray
    faces: np.ndarray
