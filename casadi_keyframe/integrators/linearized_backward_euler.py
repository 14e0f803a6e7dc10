r"""Linearized backward Euler, eqs. (10)-(12): its step, its exact backward and tangent steps,
and the paper's integrator-swapping backward step (13)-(15), which is APPROXIMATE.

Forward (Baraff-Witkin): ``A dv = b``, ``A = M - dt D - dt^2 K``, ``b = dt (f_n + dt K v_n +
e_n)`` at ``t_n``; pinned and attached components get a prescribed ``dv`` (the modified CG's
filter); A's free block is gathered into the pass's fixed pattern so a sparse Cholesky
analyses it once.  Backward: :meth:`~LinearizedBackwardEuler.step_vjp` is the exact adjoint
of this scheme (the same solve plus the force laws' second-derivative contractions);
:meth:`~LinearizedBackwardEuler.swapped_step_vjp` the paper's approximate one (the adjoint
of full backward Euler, first derivatives only, at the step's end state).  Tangent:
:meth:`~LinearizedBackwardEuler.step_jvp`.  The derivation, the swap's two deviations from
a literal reading and what the mix costs: ``docs/explanations/linearized_step.md``.
"""
from __future__ import annotations

import warnings
import weakref
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..linear import SolveError, SolveInfo, System, linear_solver
from ..models.base import BlockJacobians, ForceJacobians, StepHold
from ..models.blocks import GrowingPattern, SparseJacobian
from ..state import SimulationError, State
from .base import Integrator, Workspace, free_components, mass_diagonal
from .held_solve import (adjoint_multiplier, held_q, held_rhs, projected_matrix,
                         projected_product, sliding_step)
from .released import RANK, ReleasedFactor, released_directions

MAX_REVISIONS = 20  # a step solved again at most this often when its end shows it chose wrong
# (a sheet landing at an angle lets go of a row of arriving particles per revision)


def step_matrices(model, x, v, dt, t=0.0, with_df_dx=False, interactions=None):
    """``(A, K)`` of an implicit step linearized at (x, v) at time t, both sparse ``3n x 3n``,
    ``A = M - dt D - dt^2 K``; with ``with_df_dx`` also the full force Jacobian ``df/dx``
    (unclamped, damping included)."""
    K, D, *df_dx = model.jacobians(x, v, t, with_df_dx=with_df_dx, interactions=interactions)
    return ((sp.diags(mass_diagonal(model)) - dt * D - dt * dt * K).tocsr(), K, *df_dx)


@dataclass(frozen=True)
class LinearizedStep:
    """What a linearized step keeps: what it decided (``decisions``: what the forces act
    over at its start, self-contact pairs, springs taken taut, the held set), how its linear
    solve went, within the integrator's memory budget the prepared step matrix (``factor``,
    e.g. its Cholesky factor) for the derivative passes, the set its hold held
    (:class:`~casadi_keyframe.models.contact.hold.HeldSet`, None if none) and how many times it was
    solved (more than once when it was revised)."""

    decisions: object
    solve: SolveInfo
    factor: object = None
    held: object = None
    solves: int = 1


@dataclass(frozen=True)
class StepSystem:
    """A step's matrix as the linear solver sees it (``matrix``: A, or with a held set the
    projected ``S A S + M P``), the product ``product(y) = A y`` of the step matrix itself
    (flat), and its stiffness ``K`` and, when asked, ``df_dx``, each with a ``matvec``;
    ``plain``: with a held set, A's free block unprojected (CSC)."""

    matrix: System
    product: object
    K: object
    df_dx: object = None
    plain: object = None


class StepWorkspace(Workspace):
    """A pass's :class:`Workspace` plus the pattern its step matrices are gathered into, the
    bytes of factorisations its records keep and what the last step carried to the next
    (the model's ``carried_decisions``: a particle the hold pulled is released, springs
    taken taut stay taut)."""

    def __init__(self, plan, pattern: GrowingPattern):
        super().__init__(plan)
        self.pattern = pattern
        self.kept_bytes = 0
        self.carried = None  # what the last step carried
        self.planned = None  # what the next step decides, when an inverse step chose it
        self.family_blocks = {}  # each family's last blocks, for a revision of another's


class LinearizedBackwardEuler(Integrator):
    """Linearized implicit Euler for models with ``forces`` and block Jacobians
    (``jacobian_blocks``: cloth).

    ``solver`` is "auto" (CHOLMOD, SuperLU or CG by size and what is installed), "cholmod",
    "direct" (SuperLU), "cg" (modified PCG) or a solver object (:mod:`casadi_keyframe.linear`);
    ``tol`` is CG's relative tolerance for the steps and ``adjoint_tol`` for the backward and
    tangent steps' solves: a gradient needs fewer digits than a trajectory.  A forward pass
    that keeps its records keeps each step's factorisation in them (direct solvers) while
    their total stays within ``max_factor_memory`` bytes, and the backward and tangent steps
    solve with those instead of assembling and factorising again.
    """

    name = "linearized_backward_euler"
    requires = ForceJacobians

    def __init__(self, solver="auto", tol: float = 1e-10, adjoint=None,
                 adjoint_tol: float = 1e-8, max_factor_memory: float = 2 * 2 ** 30):
        if adjoint is not None:
            warnings.warn(
                "LinearizedBackwardEuler(adjoint=...) is deprecated and has no effect: the "
                "gradient route chooses the backward pass (gradient='adjoint' for the exact "
                "one, 'swapped' for the paper's approximate one)", DeprecationWarning,
                stacklevel=2)
        if not max_factor_memory >= 0:
            raise ValueError(f"max_factor_memory must be >= 0 bytes, got {max_factor_memory}")
        options = {"tol": tol} if solver in ("cg", "auto") else {}
        self.linear_solver = linear_solver(solver, **options)
        self._plans = weakref.WeakKeyDictionary()  # per model: analyses kept across passes
        self.solver = getattr(self.linear_solver, "name", type(self.linear_solver).__name__)
        self.tol, self.adjoint_tol = tol, adjoint_tol
        self.max_factor_memory = max_factor_memory

    def init(self, model) -> StepWorkspace:
        self.check_model(model)
        pattern = (GrowingPattern(model.step_pattern) if isinstance(model, BlockJacobians)
                   else None)
        return StepWorkspace(self.plan(model), pattern)

    def carry(self, model, record):
        """What the step carried to the next (the model's ``carried_decisions``: the
        particles its hold pulled and released, the springs it took taut)."""
        return model.carried_decisions(record.decisions)

    def resume(self, work, carried) -> None:
        work.carried = carried

    def plan(self, model):
        """The linear solver's plan for ``model``, made at the first pass and kept while the
        model lives, so every pass over it reuses the analyses of its patterns."""
        plan = self._plans.get(model)
        if plan is None:
            plan = self._plans[model] = self.linear_solver.init(model.free_mask())
        return plan

    def release(self, trajectory) -> None:
        """Give the factorisations a forward pass kept in ``trajectory``'s records back to the
        plan (after its last backward or tangent pass), so the next pass reuses them."""
        for record in trajectory.records:
            if record.factor is not None:
                record.factor.release()

    def step_system(self, model, x, v, t, dt, work, with_df_dx=False, interactions=None,
                    held=None) -> StepSystem:
        """The :class:`StepSystem` at (x, v, t): K and df/dx the model's
        :class:`~casadi_keyframe.models.blocks.Blocks`, A's free block gathered into the
        pass's pattern (projected with a ``held`` set); or, for a model with sparse
        ``jacobians`` only, those matrices."""
        if work.pattern is None:
            A, *jacobians = step_matrices(model, x, v, dt, t, with_df_dx, interactions)
            return StepSystem(work.plan.system(A), A.dot, *map(SparseJacobian, jacobians))
        K, D, *df_dx = model.jacobian_blocks(x, v, t, with_df_dx, interactions,
                                             reuse=work.family_blocks)
        A = K.scaled_sum([D], [-dt * dt, -dt], diagonal=model.masses)
        pattern = work.pattern
        data = pattern.values(A)
        product = lambda y: A.matvec(y).ravel()  # noqa: E731 (A is symmetric)
        solved, plain = product, None
        shape = (pattern.pattern.size,) * 2
        if held is not None:
            product = sliding_step(product, held)
            plain = sp.csc_matrix((data, pattern.pattern.indices, pattern.pattern.indptr),
                                  shape=shape)
            data, solved = projected_matrix(pattern.pattern, data, product, held, model.masses)
        block = sp.csc_matrix((data, pattern.pattern.indices, pattern.pattern.indptr),
                              shape=shape)
        return StepSystem(System(block, solved, solved, pattern.pattern), product, K,
                          *(df_dx or [None]), plain=plain)

    @staticmethod
    def _held(model, decisions):
        """The set a step's ``decisions`` hold, or None (a model that holds nothing)."""
        return model.held(decisions) if isinstance(model, StepHold) else None

    def _factor(self, work, system, n: int, keep: bool = False, what: str = "step"):
        try:
            return work.factor(system, keep)
        except SolveError as err:
            raise SimulationError(f"{what} {n + 1}: {err}", n + 1) from err

    def step(self, model, state, external, n, dt, work=None):
        """Step ``n`` (from t = n dt) under ``external`` (``(n, 3)``); raises SimulationError
        if the solve fails, the state is not finite or the cloth blows up."""
        work = self.init(model) if work is None else work
        x, v, t = state.x, state.v, n * dt
        if work.planned is not None:  # decided by force_for for this very step
            found, work.planned = work.planned, None
        else:
            found = model.step_decisions(x, v, t, dt, work.carried)
        f = (model.forces(x, v, t, found) + external).ravel()
        z = (model.prescribed_velocity(x, t, dt) - v).ravel()
        base = None  # (factor, decisions): what a revision that only releases borders
        for revision in range(MAX_REVISIONS + 1):
            held = self._held(model, found)
            if base is None:
                system = self.step_system(model, x, v, t, dt, work, interactions=found,
                                          held=held)
                b = dt * (f + dt * system.K.matvec(v).ravel())
                factor, keep = self._step_factor_kept(work, system, n)
                base = (factor, found)
            try:
                if held is None:
                    dv, info = factor.solve(b, z, x0=work.warm)
                    work.warm = dv
                else:
                    rhs, zc = held_rhs(held, b, system.product, z, v, work.plan.free)
                    y, info = factor.solve(rhs, x0=work.warm)
                    work.warm, dv = y, zc + y
                    found = model.solved_decisions(found, system.product(dv) - b)
            except SolveError as err:
                raise SimulationError(f"step {n + 1}: {err}", n + 1) from err
            x1 = x + dt * (v + dv.reshape(v.shape))
            revised, again = model.revised_decisions(found, x, v, t, dt, x1)
            if not again:
                found = revised  # what it stands by, with what it leaves to the next step
                break
            if revision == MAX_REVISIONS:
                break
            found = revised  # the step chose wrong: solve it again with the revision
            bordered = self._bordered(model, work, system, base, found)
            if bordered is None:  # a new matrix: factorise it
                if keep:
                    base[0].release()
                base = None
            factor = bordered
        work.kept_bytes += factor.nbytes if keep else 0
        work.carried = model.carried_decisions(found)
        v1 = v + dv.reshape(v.shape)
        model.check_state(x1, v1, n + 1)
        return State(x1, v1), LinearizedStep(found, info, factor if keep else None,
                                             self._held(model, found), revision + 1)

    def _bordered(self, model, work, system, base, found):
        """The prepared matrix of a revision that only lets particles go (nothing else in
        ``found`` differs from the ``base`` factor's decisions), bordered on the released
        directions (:mod:`.released`); None if more changed, or too much to pay."""
        factor, decided = base
        old, new = self._held(model, decided), self._held(model, found)
        if (not work.plan.worth_keeping or system.plain is None or old is None
                or any(a is not b for a, b in zip(decided, found)
                       if a is not old and b is not new)):
            return None
        Q = released_directions(old, new, model.n)
        if Q is None or not 0 < Q.shape[1] <= RANK:
            return None
        return ReleasedFactor(factor, old, Q, system.plain, work.plan.free,
                              projected_product(system.product, new, model.masses))

    def _step_factor_kept(self, work, system, n):
        """The step matrix's factorisation and whether the pass keeps it for the derivative
        passes (within the memory budget)."""
        keep = (work.keep and work.plan.worth_keeping
                and work.kept_bytes < self.max_factor_memory)
        factor = self._factor(work, system.matrix, n, keep)
        if keep and work.kept_bytes + factor.nbytes > self.max_factor_memory:
            keep = False  # known only now for the first factor of a pattern
        return factor, keep

    def step_vjp(self, model, start, end, record, n, dt, cotangent, work=None):
        """The exact backward step of the linearized scheme (module docstring)."""
        work = self.init(model) if work is None else work
        shape, t = start.x.shape, n * dt
        free = free_components(model, shape).ravel()
        ax, av = free * cotangent.x.ravel(), free * cotangent.v.ravel()
        held, x, v, dv = record.held, start.x, start.v, end.v - start.v
        factor, system = self._step_factor(model, start, t, dt, work, record, n)
        w = av + dt * ax
        if held is None:
            lam = self._derivative_solve(work, factor, w, n, transpose=True)
        else:  # the held solve's multipliers (see held_solve)
            lam = self._derivative_solve(work, factor, held.unheld_part(w).ravel(), n,
                                         transpose=True)
        bx, bv = model.linearization_vjp(x, v, t, lam.reshape(shape), end.v, dv, dt,
                                         interactions=record.decisions)
        ax = ax + bx.ravel()
        av = w + bv.ravel() + dt * dt * system.K.matvec(lam, transpose=True).ravel()
        if held is not None:  # the normals' and targets' derivatives
            full = adjoint_multiplier(held, lam, w, system.product).reshape(shape)
            cx, cv = model.hold_vjp(x, v, t, dt, held, full, held_q(held, dv, v),
                                    held.held_part(full))
            ax, av = ax + cx.ravel(), av + cv.ravel()
        ax, av = free * ax, free * av
        return State(ax.reshape(shape), av.reshape(shape)), (dt * lam).reshape(shape)

    def step_jvp(self, model, start, end, record, n, dt, tangent, d_external, work=None):
        """The exact tangent step of the linearized scheme (module docstring)."""
        work = self.init(model) if work is None else work
        shape, t = start.x.shape, n * dt
        free = free_components(model, shape)
        dx, dv = free * tangent.x, free * tangent.v
        factor, system = self._step_factor(model, start, t, dt, work, record, n)
        rhs = (dt * np.asarray(d_external).ravel() + dt * dt * system.K.matvec(dv).ravel()
               + model.linearization_jvp(start.x, start.v, t, end.v, end.v - start.v, dt, dx,
                                         dv, interactions=record.decisions).ravel())
        held = record.held
        if held is None:
            ddv = self._derivative_solve(work, factor, rhs, n, transpose=False)
        else:  # the held solve's tangent (see held_solve)
            q = held_q(held, end.v - start.v, start.v)
            rhs = (held.unheld_part(rhs).ravel()
                   + model.hold_jvp(start.x, start.v, t, dt, held, q, dx, dv).ravel())
            normal = held.held_part(rhs).ravel()
            ddv = normal + self._derivative_solve(
                work, factor, held.unheld_part(rhs - system.product(normal)).ravel(), n,
                transpose=False)
        dv1 = free * (dv + ddv.reshape(shape))
        return State(free * (dx + dt * dv1), dv1)

    def swapped_step_vjp(self, model, start, end, record, n, dt, cotangent, work=None):
        """APPROXIMATE: the paper's integrator-swapping backward step, eqs. (13)-(15): the
        exact adjoint of full backward Euler at the step's end state (module docstring)."""
        work = self.init(model) if work is None else work
        shape, t = start.x.shape, (n + 1) * dt
        free = free_components(model, shape).ravel()
        ax, av = free * cotangent.x.ravel(), free * cotangent.v.ravel()
        later = work.records[n + 1] if n + 1 < len(work.records) else None  # step n+1's A
        found = model.interactions(end.x) if later is None else later.decisions
        held = None if later is None else later.held
        if (later is not None and later.factor is not None and later.factor.usable
                and work.pattern is not None):
            df_dx = model.force_jacobian_blocks(end.x, end.v, t, found)
            factor = later.factor
        else:
            system = self.step_system(model, end.x, end.v, t, dt, work, True, found, held)
            df_dx = system.df_dx
            factor = self._factor(work, system.matrix, n, what="derivative of step")
        w = av + dt * ax
        if held is not None:  # step n+1's held set, projected as its matrix is
            w = held.unheld_part(w).ravel()
        mu = self._derivative_solve(work, factor, w, n, transpose=True)
        ax = free * (ax + dt * df_dx.matvec(mu, transpose=True).ravel())
        av = free * (mass_diagonal(model) * mu)
        return State(ax.reshape(shape), av.reshape(shape)), (dt * mu).reshape(shape)

    def _step_factor(self, model, start, t, dt, work, record, n):
        """Step n's prepared matrix (kept by the forward pass, or made again) and its
        :class:`StepSystem` (its K and the step matrix's product)."""
        if record.factor is not None and record.factor.usable and work.pattern is not None:
            K, D = model.jacobian_blocks(start.x, start.v, t, interactions=record.decisions)
            product = None
            if record.held is not None:  # the held solve needs A y
                A = K.scaled_sum([D], [-dt * dt, -dt], diagonal=model.masses)
                product = sliding_step(lambda y: A.matvec(y).ravel(), record.held)
            return record.factor, StepSystem(None, product, K)
        system = self.step_system(model, start.x, start.v, t, dt, work,
                                  interactions=record.decisions, held=record.held)
        return self._factor(work, system.matrix, n, what="derivative of step"), system

    def _derivative_solve(self, work, factor, b, n: int, transpose: bool):
        """A solve of a backward or tangent step, warm-started from the pass's last one."""
        solve = factor.solve_transpose if transpose else factor.solve
        try:
            out, _ = solve(b, x0=work.warm, tol=self.adjoint_tol)
        except SolveError as err:
            raise SimulationError(f"derivative of step {n + 1}: {err}", n + 1) from err
        work.warm = out
        return out

    def force_for(self, model, x, v, v1, n: int, dt: float, work=None) -> np.ndarray:
        """The inverse step: the external force ``(n, 3)`` under which :meth:`step` from
        ``(x, v)`` at step ``n`` ends with velocities ``v1`` (so positions ``x + dt v1``).
        Exact for the free particles; the constrained ones follow their prescribed motion
        whatever the force (``v1`` there is ignored), and so do the normal velocities of the
        particles the step holds.  With the pass's ``work``, the step it is for starts from
        the decisions this one made (particles held, springs taut), so it lands exactly."""
        t = n * dt
        found = model.step_decisions(x, v, t, dt, None if work is None else work.carried)
        prescribed = model.prescribed_velocity(x, t, dt)
        for _ in range(MAX_REVISIONS + 1):  # the decisions the step will stand by at x1
            held = self._held(model, found)
            dv = np.where(model.free_mask(), (v1 - v).ravel(), (prescribed - v).ravel())
            if held is not None:
                dv = (held.unheld_part(dv) + held.prescribed(v)).ravel()
            found, again = model.revised_decisions(found, x, v, t, dt,
                                                   x + dt * (v + dv.reshape(v.shape)))
            if not again:
                break
        if work is not None:
            work.planned = found
        A, K = step_matrices(model, x, v, dt, t, interactions=found)
        pushed = None if held is None else held.pushed(model.n)  # friction: no control's
        if pushed is not None:
            pushed = pushed - held.sliding_product(dv)
        return ((A @ dv / dt - dt * (K @ v.ravel())).reshape(v.shape)
                - model.forces(x, v, t, found) - (0 if pushed is None else pushed / dt))

    def decides_per_step(self, model) -> bool:
        """True for a model whose steps decide something the symbolic step takes: which
        particles to hold, which springs to take taut."""
        return model.decision_parameters().size > 0

    @staticmethod
    def step_parameters(model, t: float, dt: float, record=None) -> np.ndarray:
        """The symbolic step's S for the step from t: the scene then, attachment targets at
        t + dt, and what the step ``record`` decided (springs it took taut, the particles it
        held and the bodies over the step: the model's ``decision_parameters``)."""
        decided = model.decision_parameters(None if record is None else record.decisions, t, dt)
        return np.concatenate([model.scene_parameters(t), model.constraint_targets(t + dt),
                               decided])

    def symbolic_step(self, model) -> ca.Function:
        """``(X, V, E, dt, S) -> (X+, V+)``: the linearized step in CasADi, for exact reverse
        mode; S from :meth:`step_parameters` (with what the numeric step decided).

        K and D come from the model's :meth:`symbolic_jacobians` (the same kernels as the
        numeric step), so second derivatives of the forces enter through them; the linear
        solve is differentiated exactly (``ldl``).  For small systems only.
        """
        n, d = model.n, model.dim
        n_scene = model.scene_parameters(0.0).size
        n_targets = model.constraint_targets(0.0).size
        n_decided = model.decision_parameters().size
        n_s = self.step_parameters(model, 0.0, 1.0).size
        X, V, E = (ca.SX.sym(s, d, n) for s in "XVE")
        dt, S = ca.SX.sym("dt"), ca.SX.sym("S", n_s)
        scene, decided = S[:n_scene], S[n_s - n_decided:]
        f = ca.vec(model.symbolic_forces(X, V, scene, *([decided] if n_decided else [])))
        K, D = model.symbolic_jacobians(X, V, scene, decided if n_decided else None)
        mass = np.repeat(model.masses, d)
        A = ca.diag(ca.DM(mass)) - dt * D - dt * dt * K
        b = dt * (f + ca.vec(E) + dt * ca.mtimes(K, ca.vec(V)))
        prescribed = ca.vec(model.prescribed_velocity_symbolic(
            X, S[n_scene:n_scene + n_targets], dt) - V)
        free = model.free_mask()
        fi, ci = np.flatnonzero(free).tolist(), np.flatnonzero(~free).tolist()
        Xm, Vm, Em = (ca.MX.sym(s, d, n) for s in "XVE")
        dtm, Sm = ca.MX.sym("dt"), ca.MX.sym("S", n_s)
        held = model.symbolic_hold(X, V, decided, dt) if isinstance(model, StepHold) else None
        if held is None:  # nothing held by the step
            system = ca.Function("lbe_system", [X, V, E, dt, S], [A, b, prescribed])
            Am, bm, dvm = system(Xm, Vm, Em, dtm, Sm)
            dv = dvm
            rhs = bm[fi] - (ca.mtimes(Am[fi, ci], dvm[ci]) if ci else 0)
            dv[fi] = ca.solve(Am[fi, fi], rhs, "ldl")
        else:
            system = ca.Function("lbe_system", [X, V, E, dt, S], _held_system(
                model.n, V, held, A, b, prescribed, mass, free))
            Am, rhs, dvm = system(Xm, Vm, Em, dtm, Sm)
            dv = dvm
            dv[fi] = dvm[fi] + ca.solve(Am[fi, fi], rhs[fi], "ldl")
        v_next = Vm + ca.reshape(dv, d, n)
        return ca.Function("lbe_step", [Xm, Vm, Em, dtm, Sm], [Xm + dtm * v_next, v_next])


def _held_system(n, V, held, A, b, prescribed, mass, free):
    """``(A_hat, S (b - A z), z)`` of the symbolic step holding the particles of ``held``
    (their ``(normals, targets)``, zero where none is held, and with friction their body
    velocities, normal and stick flags and sliding impulses; see :mod:`.held_solve`); z is
    the prescribed part of dv on every component."""
    normals, targets, *friction = held
    blocks = [ca.mtimes(normals[:, k], normals[:, k].T) for k in range(n)]
    along = normals * ca.repmat(targets - ca.sum1(normals * V), 3, 1)
    if friction:  # P = s I + (a - s) n n^T, z = a n (c - n . v) + s T (v_body - v)
        velocity, normal, stick, pushed, matrices = friction
        A = A + ca.diagcat(*[ca.reshape(matrices[:, k], 3, 3).T for k in range(n)])
        blocks = [stick[k] * ca.SX.eye(3) + (normal[k] - stick[k]) * blocks[k]
                  for k in range(n)]
        slip = velocity - V
        slip = slip - normals * ca.repmat(ca.sum1(normals * slip), 3, 1)
        along = ca.repmat(normal, 3, 1) * along + ca.repmat(stick, 3, 1) * slip
        b = b + ca.vec(pushed)
    P = ca.diagcat(*blocks)
    keep = ca.SX.eye(3 * n) - P
    mask = ca.DM(free.astype(float))
    z = mask * ca.vec(along) + (1 - mask) * prescribed
    A_hat = ca.mtimes([keep, A, keep]) + ca.mtimes(ca.diag(ca.DM(mass)), P)
    return [A_hat, ca.mtimes(keep, b - ca.mtimes(A, z)), z]
