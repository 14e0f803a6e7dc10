r"""The transcription where the controls are fewer than a force per free particle (initial
velocities, forces on some particles): the free particles' positions at frames 1..N and the
problem's controls ``u`` are the unknowns ``w = (z, u)``, and every step is an equality
constraint (direct multiple shooting with every step a node, DESIGN.md section 3d),

    d_n(w) = S (e_n(x_{n-1}, x_n, x_{n+1}) - stored_n - B_n u) = 0   on every free component,

``e_n`` the inverse of the problem's own step (:mod:`.transcription`), ``B`` the controls'
forces and ``x_{-1} = x_0 - dt (v_0 + V u)``, ``V`` their initial velocities, so that the first
step's velocity is the controlled one.  ``S = dt^2 / m`` makes each defect the distance (m) by
which the step misses its next position.  The controls' maps ``B`` and ``V`` are read once
from their symbolic form (:meth:`~casadi_keyframe.controls.Controls.symbolic`) and checked
against their numeric one.  The defects' Jacobian is the transcription's control Jacobian on
the free rows, beside the controls' columns ``-S B`` and the first step's ``-dt S de_0/dx_{-1} V``;
their curvature, weighed by multipliers, is one CasADi Hessian per step, mapped over the steps
(as :mod:`.curvature` does for the effort), the first step's carried to ``u`` through ``V``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...controls import InitialVelocity, StepForces
from .curvature import weighted_step_hessian
from .interior import ones_pattern
from .transcription import (Buffered, Transcription, TranscriptionError, check_steps,
                            full_forces, inverse_step_function)

WRITTEN = (StepForces, InitialVelocity)  # the controls whose maps are linear and read here


def check_defects(problem) -> None:
    """Refuse what the defects cannot write (TranscriptionError naming it and what to use)."""
    check_steps(problem)
    if not isinstance(problem.controls, WRITTEN):
        raise TranscriptionError(
            f"{problem.name}: the transcription writes per-step forces and initial "
            f"velocities; this problem's controls are {type(problem.controls).__name__} "
            f"({problem.controls.label}): solve it with method='lbfgsb'")
    if full_forces(problem):
        raise TranscriptionError(
            f"{problem.name}: per-step forces on every free particle follow from the "
            "positions in closed form: use Transcription, not StepDefects")
    found = [f.name for f in getattr(problem.model, "families", ())
             if not getattr(f, "fixed_pairs", True)]
    if found:
        raise TranscriptionError(
            f"{problem.name}: its {', '.join(found)} acts over pairs found per state, which "
            "the defects (the step as a constraint) cannot write, and its controls are "
            "fewer than a force per free particle, so no replay can write it instead: "
            "build it without (self_contact=None), or solve it with method='lbfgsb'")


def _sparse(fn: ca.Function, arg) -> sp.csc_matrix:
    """The sparse value of ``fn``'s one output at ``arg``."""
    out = fn(arg)
    pattern = out.sparsity()
    return sp.csc_matrix((np.asarray(out.nonzeros(), float),
                          np.asarray(pattern.row()), np.asarray(pattern.colind())),
                         shape=out.shape)


def control_maps(problem):
    """``(B, V)``: the controls' per-step forces ``(N 3n, size)`` and initial velocities
    ``(3n, size)`` as sparse matrices (zero where the controls have none), from their symbolic
    map, checked against :meth:`external` and :meth:`velocity_offset` at a random ``u``."""
    controls, n, N = problem.controls, problem.model.n, problem.steps
    U = ca.SX.sym("u", controls.size)
    forces, offset = controls.symbolic(U)
    B = sp.csc_matrix((N * 3 * n, controls.size))
    V = sp.csc_matrix((3 * n, controls.size))
    if forces is not None:
        stacked = ca.vertcat(*(ca.vec(f) for f in forces))
        B = _sparse(ca.Function("B", [U], [ca.jacobian(stacked, U)]), np.zeros(controls.size))
    if offset is not None:
        V = _sparse(ca.Function("V", [U], [ca.jacobian(ca.vec(offset), U)]),
                    np.zeros(controls.size))
    u = np.random.default_rng(0).standard_normal(controls.size)
    ext, off = controls.external(u), controls.velocity_offset(u)
    for name, M, numeric in (("forces", B, ext), ("initial velocities", V, off)):
        if not np.allclose(M @ u, 0.0 if numeric is None else np.ravel(numeric), atol=1e-12):
            raise TranscriptionError(f"{problem.name}: the controls' {name} are not the "
                                     "linear map their symbolic form says: solve it with "
                                     "method='lbfgsb'")
    return B.tocsr(), V.tocsr()


class StepDefects(Transcription):
    """The defects of the module docstring on ``problem``: ``values(w)``, ``jacobian(w)``
    and ``curvature(w, lam)``, ``w = (z, u)`` of :attr:`width`; ``size`` the positions' part,
    ``nu`` the controls'; one row per step and free component, step-major."""

    check = staticmethod(check_defects)

    def __init__(self, problem):
        super().__init__(problem)
        self.B, self.V = control_maps(problem)
        self.nu = problem.controls.size
        self.width = self.size + self.nu
        self.rows = self.N * self.nf
        m = np.repeat(problem.model.masses, 3)[self.free_flat]
        self.scale = np.tile(self.dt ** 2 / m, self.N)
        self._B_free = self.B[(np.arange(self.N)[:, None] * 3 * self.n
                               + self.free_flat[None, :]).ravel()]
        step = inverse_step_function(self.model, self.dt)
        frames = [ca.MX.sym(s, 3, self.n) for s in ("before", "now", "next")]
        scene = ca.MX.sym("scene", self.scene.shape[0])
        behind = ca.jacobian(step(*frames, scene), ca.vec(frames[0]))
        self._behind = ca.Function("behind", [*frames, scene], [behind])
        self._curvature = None  # made at the first call (its build is the costly part)

    def row_components(self) -> np.ndarray:
        """Every free component: each one's step is a constraint."""
        return self.free_flat

    def split(self, w):
        w = np.asarray(w, float)
        return w[:self.size], w[self.size:]

    def at(self, u) -> None:
        """Set the first step's start to the controls ``u``'s (``v_start``, ``x_before``)."""
        offset = (self.V @ u).reshape(self.n, 3)
        self.v_start = self.problem.v0 + offset
        self.x_before = self.problem.x0 - self.dt * self.v_start

    def values(self, w) -> np.ndarray:
        """The defects ``d(w)`` (m)."""
        z, u = self.split(w)
        self.at(u)
        e = (self.forces(z) - self.stored).reshape(self.N, -1) - (self.B @ u).reshape(self.N, -1)
        return self.scale * e[:, self.free_flat].ravel()

    def jacobian(self, w) -> sp.csr_matrix:
        """``dd/dw``, sparse and exact (module docstring)."""
        z, u = self.split(w)
        self.at(u)
        Jz = self.control_jacobian(z)
        x = self.frames(z)
        behind = _sparse_out(self._behind, self._stacked(x), 0, self.scene[:, :1])
        first = sp.vstack([behind.tocsr()[self.free_flat],
                           sp.csr_matrix((self.rows - self.nf, 3 * self.n))])
        Ju = -self._B_free - self.dt * (first @ self.V)
        D = sp.diags(self.scale)
        return (D @ sp.hstack([Jz, Ju])).tocsr()

    def jacobian_pattern(self) -> sp.csr_matrix:
        """Every entry :meth:`jacobian` can hold, as ones (whatever the point)."""
        if self._jacobian is None:
            self.control_jacobian(self.unknowns(self.base))
        p = self._jacobian
        Jz = sp.csr_matrix((np.ones(p.indices.size), p.indices, p.indptr), shape=p.shape)
        pattern = self._behind.sparsity_out(0)
        behind = sp.csr_matrix((np.ones(pattern.nnz()), pattern.get_triplet()),
                               shape=pattern.shape)[self.free_flat]
        first = sp.vstack([behind, sp.csr_matrix((self.rows - self.nf, 3 * self.n))])
        Ju = ones_pattern(self._B_free) + first @ ones_pattern(self.V)
        return ones_pattern(sp.hstack([Jz, Ju]))

    def curvature(self, w, lam) -> sp.csr_matrix:
        """``sum_k lam_k d^2 d_k / dw^2`` (``width x width``)."""
        return self._curvature_of()(w, lam)

    def curvature_pattern(self) -> sp.csr_matrix:
        """Every entry :meth:`curvature` can hold, as ones."""
        return self._curvature_of().pattern()

    def _curvature_of(self) -> "DefectCurvature":
        if self._curvature is None:
            self._curvature = DefectCurvature(self)
        return self._curvature


def _sparse_out(fn, stacked, step, scene) -> sp.csc_matrix:
    """``fn``'s output at step ``step`` of the mapped inputs ``stacked`` (each ``(N, n, 3)``)."""
    out = fn(*(a[step].T for a in stacked), scene)
    pattern = out.sparsity()
    return sp.csc_matrix((np.asarray(out.nonzeros(), float), np.asarray(pattern.row()),
                          np.asarray(pattern.colind())), shape=out.shape)


class DefectCurvature:
    """``sum_n <W_n, d^2 e_n>``, the defects' second derivatives weighed by multipliers: one
    CasADi Hessian of ``<W, e(x_{n-1}, x_n, x_{n+1})>`` per step, mapped over the steps;
    steps 1..N-1 gathered onto the positions, the first step carried through ``x_{-1}`` to
    the controls (``dx_{-1}/du = -dt V``)."""

    def __init__(self, d: StepDefects):
        self.d = d
        n, N = d.n, d.N
        fn, triplets = weighted_step_hessian(d)
        self._hessian = Buffered(fn.map(N))
        rows, cols = (np.asarray(ix) for ix in triplets)
        self._local = rows, cols
        self._nnz = rows.size
        column = np.full(3 * n, -1)
        column[d.free_flat] = np.arange(d.nf)
        later = np.arange(1, N)[:, None]
        self._rows, self._cols = (self._global(ix, later, column, n) for ix in (rows, cols))
        self._keep = (self._rows >= 0) & (self._cols >= 0)
        self._first = self._first_map(column, n)

    def _global(self, local, steps, column, n):
        """The unknowns' index of each (step, local index in frames n-1, n, n+1); -1 for
        the start or a prescribed component."""
        frame = steps - 1 + local[None, :] // (3 * n)
        col = column[local % (3 * n)][None, :]
        return np.where((frame >= 1) & (col >= 0), (frame - 1) * self.d.nf + col, -1).ravel()

    def _first_map(self, column, n) -> sp.csr_matrix:
        """The first step's frames ``(x_{-1}, x_0, x_1)`` in the unknowns ``w``: ``9n x width``."""
        d = self.d
        free = np.flatnonzero(column >= 0)
        nxt = sp.csr_matrix((np.ones(free.size), (6 * n + free, column[free])),
                            shape=(9 * n, d.width))
        behind = sp.vstack([-d.dt * d.V, sp.csr_matrix((6 * n, d.nu))])
        return (nxt + sp.hstack([sp.csr_matrix((9 * n, d.size)), behind])).tocsr()

    def __call__(self, w, lam) -> sp.csr_matrix:
        d = self.d
        z, u = d.split(w)
        d.at(u)
        W = np.zeros((d.N, 3 * d.n))
        W[:, d.free_flat] = (d.scale * np.asarray(lam, float)).reshape(d.N, d.nf)
        x = d.frames(z)
        (values,) = self._hessian(*d._stacked(x), d.scene_columns(), W)
        values = values.reshape(d.N, self._nnz)
        later = values[1:].ravel()
        k = self._keep
        H = sp.csr_matrix((later[k], (self._rows[k], self._cols[k])), shape=(d.width,) * 2)
        rows, cols = self._local
        H0 = sp.csr_matrix((values[0], (rows, cols)), shape=(9 * d.n,) * 2)
        P = self._first
        return (H + P.T @ H0 @ P).tocsr()

    def pattern(self) -> sp.csr_matrix:
        d, k = self.d, self._keep
        H = sp.csr_matrix((np.ones(k.sum()), (self._rows[k], self._cols[k])),
                          shape=(d.width,) * 2)
        rows, cols = self._local
        H0 = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(9 * d.n,) * 2)
        P = ones_pattern(self._first)
        return ones_pattern(H + P.T @ H0 @ P)
