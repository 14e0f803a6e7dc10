r"""A control problem written in positions: the free particles' positions at every frame are
the unknowns, and the forces follow from them in closed form by the inverse of the problem's
own step (DESIGN.md section 3d).

The linearized backward Euler step ``A dv = dt (f + dt K v_n + e)``, ``A = M - dt D -
dt^2 K``, is linear in the new velocity, so the external force of step n is

    e_n = M (v_{n+1} - v_n) / dt - f(x_n, v_n) - D (v_{n+1} - v_n) - dt K v_{n+1},

with ``v_{n+1} = (x_{n+1} - x_n) / dt`` (and ``v_0`` the problem's).  Step n's force depends
on frames n-1, n and n+1 only: its Jacobian is block-banded in time and sparse in space, and
no product of step Jacobians appears.  The step is written per interaction
(:meth:`~casadi_keyframe.models.families.FamilyModel.symbolic_step`), so its CasADi function
stays small; its Jacobian is assembled from the mapped per-step Jacobians into one sparse
matrix whose pattern is fixed.

The step's discrete decisions (springs taken taut at a stop, particles held by a body) are
not decided here: :mod:`.replay` computes the controls a result returns by the integrator's
own inverse step along the replay, which decides them as ``simulate`` does.  Families that
act over pairs found per state (self-contact) have no fixed pattern and are left out of the
plan (:func:`planned_model`): the replay's inverse step writes their forces into the
controls, so the result still replays its positions.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...controls import StepForces
from ...integrators import LinearizedBackwardEuler


class TranscriptionError(ValueError):
    """A problem whose controls or model the transcription cannot write (the message says
    which and what to solve it with instead)."""


def check_steps(problem) -> None:
    """Refuse a problem whose step the transcription cannot write (TranscriptionError naming
    what and how to solve it instead): the linearized backward Euler step, a model whose
    families write their step and hold no particle on a body."""
    name = problem.name
    if not isinstance(problem.integrator, LinearizedBackwardEuler):
        raise TranscriptionError(
            f"{name}: the transcription inverts the linearized backward Euler step; this "
            f"problem steps with {type(problem.integrator).__name__}: solve it with "
            "method='lbfgsb' (or any other method of METHODS)")
    if not hasattr(problem.model, "symbolic_step"):
        raise TranscriptionError(f"{name}: {type(problem.model).__name__} does not write its "
                                 "step symbolically: solve it with method='lbfgsb'")
    if any(getattr(f, "holds", False) for f in getattr(problem.model, "families", ())):
        raise TranscriptionError(
            f"{name}: its contact holds particles on a body (collision 'guarded' or "
            "'constraint'), a decision of the step the inverse step cannot write in "
            "positions: give collision='penalty' (the paper's penalty springs, which it "
            "writes), or solve it without --method (the problem's own SOLVE)")


def planned_model(model):
    """The model whose step the transcription writes: ``model`` without its families over
    pairs found per state (self-contact: no fixed pattern, and over all pairs its symbolic
    step grows with the square of the particles), left to the replay (module docstring)."""
    restricted = getattr(model, "restricted", None)
    return model if restricted is None else restricted(lambda f: getattr(f, "fixed_pairs",
                                                                         True))


def full_forces(problem) -> bool:
    """Whether the controls are per-step forces on every free particle, so the forces
    follow from the positions in closed form (:class:`Transcription`); otherwise the states
    stay unknowns beside the controls (:mod:`.defects`)."""
    return isinstance(problem.controls, StepForces) and not _unpushed(problem).size


def _unpushed(problem) -> np.ndarray:
    """The free particles that per-step forces ``problem.controls`` leave without one."""
    model = problem.model
    free = model.free_mask().reshape(model.n, model.dim).any(axis=1)
    return np.setdiff1d(np.flatnonzero(free), problem.controls.idx)


def check_transcribable(problem) -> None:
    """Refuse a problem the transcription cannot write in closed form (TranscriptionError
    naming what and how to solve it instead): per-step forces on every free particle, the
    linearized backward Euler step, a model whose families write their step."""
    check_steps(problem)
    name = problem.name
    if not isinstance(problem.controls, StepForces):
        raise TranscriptionError(
            f"{name}: the closed-form transcription needs per-step forces on every free "
            f"particle (the forces follow from the positions); this problem's controls are "
            f"{problem.controls.label}: method='transcription' keeps the states as unknowns "
            "for it (defects.StepDefects), or solve it with method='lbfgsb'")
    missing = _unpushed(problem)
    if missing.size:
        raise TranscriptionError(
            f"{name}: the closed-form transcription needs a force on every free particle; "
            f"{missing.size} free particles (e.g. {missing[:5].tolist()}) have none: "
            "method='transcription' keeps the states as unknowns for it "
            "(defects.StepDefects), or control every free particle")


class Transcription:
    """``problem`` in positions (module docstring).

    The unknowns ``z`` are the free components of frames 1..N, frame after frame (C order
    within a frame); constrained components follow their prescribed motion, read once from
    a passive run.  :meth:`frames` maps ``z`` to positions ``(N + 1, n, 3)``,
    :meth:`forces` to each step's external force ``(N, n, 3)``, :meth:`controls` to the
    problem's controls, and :meth:`control_jacobian` gives ``du/dz`` as a sparse matrix of a
    fixed pattern.
    """

    def __init__(self, problem):
        self.check(problem)
        self.problem = problem
        model = self.model = planned_model(problem.model)
        self.n, self.N, self.dt = model.n, problem.steps, problem.dt
        self.free = model.free_mask().reshape(self.n, 3)
        self.free_flat = np.flatnonzero(self.free.ravel())
        self.nf = self.free_flat.size
        self.size = self.nf * self.N
        passive = problem.simulate(None, records=False)
        self.base = passive.x.copy()  # constrained components' prescribed motion
        self.stored = problem.external  # stored forces (not controls), per step
        self.x_before = problem.x0 - self.dt * problem.v0  # so that v_0 = (x_0 - this) / dt
        self.scene = np.stack([model.scene_parameters(k * self.dt) for k in range(self.N)],
                              axis=1) if model.scene_parameters(0.0).size else np.zeros((0, self.N))
        self._step = Buffered(inverse_step_function(model, self.dt).map(self.N))
        self.times = np.arange(self.N) * self.dt
        self.v_start = problem.v0  # v_0, whose step ``x_before`` is behind x_0
        self._jacobian = None  # its pattern, made at the first call

    check = staticmethod(check_transcribable)

    def row_components(self) -> np.ndarray:
        """The components (``3 p + d``) whose force rows :meth:`control_jacobian` gives, in
        order: the controlled particles'."""
        idx = self.problem.controls.idx
        return (idx[:, None] * 3 + np.arange(3)).ravel()

    # -- positions --------------------------------------------------------------------------
    def frames(self, z) -> np.ndarray:
        """Positions ``(N + 1, n, 3)`` of the unknowns ``z`` (frame 0 the problem's start)."""
        x = self.base.copy()
        x.reshape(self.N + 1, -1)[1:, self.free_flat] = np.reshape(z, (self.N, self.nf))
        return x

    def unknowns(self, x) -> np.ndarray:
        """The unknowns ``z`` of positions ``x`` ``(N + 1, n, 3)`` (their free components)."""
        return np.asarray(x, float).reshape(self.N + 1, -1)[1:, self.free_flat].ravel()

    def velocities(self, x) -> np.ndarray:
        """Each frame's velocity ``(N + 1, n, 3)``: ``v_0`` the problem's, then differences."""
        v = np.empty_like(x)
        v[0] = self.v_start
        v[1:] = np.diff(x, axis=0) / self.dt
        return v

    def _stacked(self, x):
        """The mapped step's inputs: frames n-1, n, n+1 of every step, each ``3 x n N`` in
        CasADi's column-major order (the C-ordered ``(N, n, 3)`` array's memory)."""
        before = np.concatenate([self.x_before[None], x[:-2]], axis=0)
        return [np.ascontiguousarray(a) for a in (before, x[:-1], x[1:])]

    def scene_columns(self) -> np.ndarray:
        """The scene of every step as the mapped step reads it: ``(N, k)``, C order (one
        column of CasADi's ``k x N`` per step)."""
        return np.ascontiguousarray(self.scene.T)

    # -- forces -----------------------------------------------------------------------------
    def forces(self, z) -> np.ndarray:
        """Every step's external force ``(N, n, 3)`` that moves the particles along ``z``
        (stored forces and controls together; constrained components' are meaningless)."""
        x = self.frames(z)
        (E,) = self._step(*self._stacked(x), self.scene_columns())
        return E.reshape(self.N, self.n, 3)

    def controls(self, z) -> np.ndarray:
        """The problem's controls along ``z``: the forces less the stored ones, on the
        controlled particles (flat, as :class:`~casadi_keyframe.controls.StepForces`)."""
        e = self.forces(z) - self.stored
        return e[:, self.problem.controls.idx].ravel()

    def control_jacobian(self, z) -> sp.csr_matrix:
        """``du/dz`` (rows: the controls, columns: the unknowns), sparse, exact: each
        family's per-interaction blocks (:meth:`~casadi_keyframe.models.families.FamilyModel.step_jacobians`)
        and the masses', gathered into a fixed pattern."""
        x = self.frames(z)
        v = self.velocities(x)
        w, q = v[1:], v[1:] - v[:-1]
        parts = self.model.step_jacobians(x[:-1], v[:-1], w, q, self.times, self.dt)
        values = [self._mass_values()] + [_frame_blocks(blocks, self.dt).ravel()
                                          for _, blocks in parts]
        if self._jacobian is None:
            self._jacobian = ControlJacobianPattern(self, [p for p, _ in parts])
        return self._jacobian.matrix(values)

    def _mass_values(self) -> np.ndarray:
        """The masses' part of each step's three frame blocks, ``M / dt^2 (1, -2, 1)``, per
        step, particle, frame and component (the diagonal)."""
        m = np.repeat(self.model.masses, 3) / self.dt ** 2
        return np.broadcast_to(np.array([1.0, -2.0, 1.0])[None, :, None] * m[None, None, :],
                               (self.N, 3, 3 * self.n)).ravel()


class ControlJacobianPattern:
    """Where every entry of the control Jacobian's per-step blocks goes: the fixed sparse
    pattern of ``du/dz`` and, for each part (the masses' diagonal, then each family's
    blocks), the index of its entries in the matrix's data (-1: a row of an uncontrolled
    component or a column of the start or a prescribed component, dropped)."""

    def __init__(self, tr, particle_lists):
        n, N = tr.n, tr.N
        self.column = -np.ones(3 * n, np.int64)
        self.column[tr.free_flat] = np.arange(tr.nf)
        self.row = -np.ones(3 * n, np.int64)
        comps = tr.row_components()
        self.row[comps] = np.arange(comps.size)
        self.width = comps.size
        self.shape = (N * comps.size, tr.size)
        self.nf, self.N = tr.nf, N
        entries = [self._diagonal(n)]
        for particles in particle_lists:
            k = particles.shape[1]
            comp = (particles[:, :, None] * 3 + np.arange(3)).reshape(-1, 3 * k)  # (P, 3k)
            entries.append(self._entries(comp[:, :, None], comp[:, None, :]))
        keys = np.concatenate([e[e >= 0] for e in entries])
        self.keys, inverse = np.unique(keys, return_inverse=True)
        self.targets, at = [], 0
        for e in entries:
            t = -np.ones(e.size, np.int64)
            valid = e.ravel() >= 0
            t[valid] = inverse[at:at + valid.sum()]
            at += valid.sum()
            self.targets.append(t)
        rows, cols = np.divmod(self.keys, self.shape[1])
        self.indices = cols
        self.indptr = np.searchsorted(rows, np.arange(self.shape[0] + 1))

    def _entries(self, rows, cols):
        """The flat keys ``row * columns + column`` of every (step, stencil, frame, row,
        column) entry of a family's blocks (-1 where dropped); ``rows`` ``(P, 3k, 1)`` and
        ``cols`` ``(P, 1, 3k)`` are component indices within a frame."""
        steps = np.arange(self.N)[:, None, None, None, None]
        frame = steps - 1 + np.arange(3)[None, None, :, None, None]  # n-1, n, n+1
        r = self.row[rows][None, :, None]
        c = self.column[cols][None, :, None]
        return self._keys(steps, frame, r, c)

    def _diagonal(self, n):
        """The keys of the masses' diagonal: (step, frame, component)."""
        steps = np.arange(self.N)[:, None, None]
        frame = steps - 1 + np.arange(3)[None, :, None]
        comp = np.arange(3 * n)[None, None, :]
        return self._keys(steps, frame, self.row[comp], self.column[comp])

    def _keys(self, steps, frame, r, c):
        row = np.where(r >= 0, steps * self.width + r, -1)
        col = np.where((c >= 0) & (frame >= 1), (frame - 1) * self.nf + c, -1)
        return np.where((row >= 0) & (col >= 0), row * self.shape[1] + col, -1).reshape(-1)

    def matrix(self, values) -> sp.csr_matrix:
        data = np.zeros(self.keys.size)
        for t, v in zip(self.targets, values):
            keep = t >= 0
            data += np.bincount(t[keep], v[keep], minlength=self.keys.size)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape)


def _frame_blocks(blocks, dt):
    """A family's ``(steps, P, 4, 3k, 3k)`` derivatives of ``G = dt f + dt^2 K w + dt D q``
    in x, v, w, q as the inverse step's ``-G / dt`` blocks in the frames n-1, n, n+1
    (``(steps, P, 3, 3k, 3k)``), with ``v_n = (x_n - x_{n-1}) / dt``, ``w = v_{n+1}``,
    ``q = v_{n+1} - v_n``."""
    gx, gv, gw, gq = (blocks[:, :, k] for k in range(4))
    ahead, behind = (gw + gq) / dt ** 2, (gv - gq) / dt ** 2
    return np.stack([behind, -gx / dt + ahead - behind, -ahead], axis=2)


class Buffered:
    """A CasADi function evaluated on numpy arrays through its buffer (no element-by-element
    conversion): inputs are arrays holding each input's nonzeros in CasADi's (column-major)
    order, outputs come back as flat arrays of each output's nonzeros."""

    def __init__(self, fn: ca.Function):
        self.fn = fn
        self.buffer, self.trigger = fn.buffer()
        self.out = [np.empty(fn.nnz_out(j)) for j in range(fn.n_out())]
        for j, r in enumerate(self.out):
            self.buffer.set_res(j, memoryview(r))

    def __call__(self, *inputs) -> list[np.ndarray]:
        held = []
        for i, a in enumerate(inputs):
            a = np.ascontiguousarray(a, dtype=np.float64).ravel()
            if a.size != self.fn.nnz_in(i):
                raise ValueError(f"{self.fn.name()} input {i}: {a.size} values, expected "
                                 f"{self.fn.nnz_in(i)}")
            held.append(a)
            self.buffer.set_arg(i, memoryview(a))
        self.trigger()
        return [r.copy() for r in self.out]


def inverse_step_function(model, dt: float) -> ca.Function:
    """The inverse step ``(X_{n-1}, X_n, X_{n+1}, S) -> e_n`` (each ``3 x n``; S the scene
    at t_n)."""
    n = model.n
    frames = [ca.MX.sym(name, 3, n) for name in ("before", "now", "next")]
    scene = ca.MX.sym("scene", model.scene_parameters(0.0).size)
    v, v1 = (frames[1] - frames[0]) / dt, (frames[2] - frames[1]) / dt
    X, V, W, Q = (ca.MX.sym(s, 3, n) for s in "XVWQ")
    S = ca.MX.sym("S", scene.shape[0])
    g = ca.Function("step_rhs", [X, V, W, Q, S], [model.symbolic_step(X, V, W, Q, S, dt)])
    mass = ca.DM(np.repeat(model.masses[None, :], 3, axis=0))
    e = mass * (v1 - v) / dt - g(frames[1], v, v1, v1 - v, scene) / dt
    return ca.Function("inverse_step", [*frames, scene], [e])
