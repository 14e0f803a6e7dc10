"""The objective as residuals, ``phi(u) = 0.5 |r(u)|^2``, linearized at a point: the matrix-free
products ``J p`` (one tangent pass along the recorded run, the integrators' exact
``step_jvp``) and ``J^T w`` (one backward pass with the residual cotangents as frame
cotangents, the exact ``step_vjp``, then the controls' pullback) that a Gauss-Newton search
needs.  ``r`` stacks every term's residual (keyframe misses, region distances, strain
excess, control effort) in the problem's term order.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse.linalg import LinearOperator

from ...simulate import backward, tangent


class ResidualMap:
    """What every residual map gives beside its ``residual``: the objective's value there."""

    residual: np.ndarray

    @property
    def value(self) -> float:
        return float(0.5 * self.residual @ self.residual)


class TermResiduals:
    """A problem's terms as one stacked residual, in its term order: the state and
    trajectory terms' on a trajectory, then the control terms' on the controls; their
    forward and transposed products split the same way."""

    def __init__(self, problem):
        terms = problem.objective_terms
        self.state = terms.state_terms + terms.trajectory_terms
        self.control = terms.control_terms
        self.controls, self.dt = problem.controls, problem.dt

    def __len__(self) -> int:
        return len(self.state) + len(self.control)

    def pieces(self, traj, u) -> list:
        return ([t.residual(traj) for t in self.state]
                + [t.residual(u, self.controls, self.dt) for t in self.control])

    def jvp(self, traj, dx, dv, du) -> list:
        """Each term's ``J du``, given the frames' tangents ``dx, dv`` along ``du``."""
        return ([t.residual_jvp(traj, dx, dv) for t in self.state]
                + [t.residual_jvp(du, self.controls, self.dt) for t in self.control])

    def state_vjp(self, traj, parts, gx, gv) -> None:
        """Add the state terms' ``J^T w`` (``parts``: the cotangents, term by term) into
        the frame cotangents ``gx, gv``."""
        for term, part in zip(self.state, parts):
            term.residual_vjp(traj, part, gx, gv)

    def control_vjp(self, parts, out):
        """``out`` plus the control terms' ``J^T w`` (``parts`` as for :meth:`state_vjp`)."""
        for term, part in zip(self.control, parts[len(self.state):len(self)]):
            out = out + term.residual_vjp(part, self.controls, self.dt)
        return out


class Linearization(ResidualMap):
    """The residual map of ``problem`` at the controls ``u``: one simulation with records,
    kept for the products until :meth:`release` (it holds the steps' factorisations).

    * ``residual``: r(u); ``value``: 0.5 |r|^2, the objective at u;
    * :meth:`jvp` ``(du) -> J du`` and :meth:`vjp` ``(w) -> J^T w``, exact for the scheme
      simulated (the aligned mesh keyframe's Jacobian excepted: see ``MeshKeyframe``);
    * :meth:`operator`: both as a scipy ``LinearOperator`` (for LSMR, ``least_squares``).
    """

    def __init__(self, problem, u):
        self.problem = problem
        self.u = problem.controls.check(u)
        self.trajectory = problem.simulate(self.u)
        self.terms = TermResiduals(problem)
        pieces = self.terms.pieces(self.trajectory, self.u)
        self._ends = np.cumsum([p.size for p in pieces])
        self.residual = np.concatenate(pieces) if pieces else np.zeros(0)
        self.products = 0  # Jacobian products so far, forward and transposed

    @property
    def shape(self) -> tuple:
        return (self.residual.size, self.u.size)

    def jvp(self, du) -> np.ndarray:
        """``J du``: the residuals' change along the controls' change ``du`` (to first order)."""
        p = self.problem
        du = np.asarray(du, dtype=float).ravel()
        offset, forces = p.controls.velocity_offset(du), p.controls.external(du)
        traj = self.trajectory
        dx, dv = tangent(p.integrator, p.model, traj, np.zeros_like(p.x0),
                         np.zeros_like(p.v0) if offset is None else offset,
                         np.zeros_like(p.external) if forces is None else forces)
        self.products += 1
        return np.concatenate(self.terms.jvp(traj, dx, dv, du))

    def vjp(self, w) -> np.ndarray:
        """``J^T w``: the controls' cotangent of the residual cotangent ``w``."""
        p, traj = self.problem, self.trajectory
        w = np.asarray(w, dtype=float).ravel()
        parts = np.split(w, self._ends[:-1])
        gx, gv = np.zeros_like(traj.x), np.zeros_like(traj.v)
        self.terms.state_vjp(traj, parts, gx, gv)
        g_external, g0 = backward(p.integrator, p.model, traj, gx, gv)
        out = self.terms.control_vjp(parts, p.controls.pullback(g_external, g0.v))
        self.products += 1
        return out

    def gradient(self) -> np.ndarray:
        """``J^T r``, the objective's gradient at u."""
        return self.vjp(self.residual)

    def operator(self) -> LinearOperator:
        return LinearOperator(self.shape, matvec=self.jvp, rmatvec=self.vjp, dtype=float)

    def release(self) -> None:
        """Hand the run's kept factorisations back (no product after this)."""
        self.problem.integrator.release(self.trajectory)


class SearchSpace:
    """Where a residual search moves: the evaluator's variables z (a smooth metric's, u =
    S z, the controls themselves, or multiple shooting's controls and nodes), the bounds on
    them, and the Jacobian products in z.  ``method`` names the search in a refusal."""

    def __init__(self, problem, ev, method: str):
        merit = getattr(getattr(ev, "ev", ev), "merit", None)
        self.merit = merit if hasattr(merit, "linearize") else None
        if self.merit is None and not hasattr(problem, "objective_terms"):
            raise ValueError(f"method {method!r} searches residuals; {problem!r} has none")
        self.problem, self.metric = problem, getattr(ev, "metric", None)
        self.lb, self.ub = problem.bounds()
        self.bounded = bool(np.isfinite(self.lb).any() or np.isfinite(self.ub).any())

    def controls(self, z):
        return z if self.metric is None else self.metric.smooth(z)

    def linearize(self, z):
        """The residual map at z: a :class:`Linearization` of the problem's controls, or
        the merit's own (multiple shooting's)."""
        if self.merit is not None:
            return self.merit.linearize(z)
        return Linearization(self.problem, self.controls(z))

    def products(self, lin, free=1.0, between=lambda: None):
        """``(z -> J_z p, w -> J_z^T w)`` at ``lin``, with only the ``free`` variables moving
        and ``between()`` run before each product."""
        smooth = (lambda v: v) if self.metric is None else self.metric.smooth

        def jvp(d):
            between()
            return lin.jvp(smooth(free * d))

        def vjp(s):
            between()
            return free * smooth(lin.vjp(s))

        return jvp, vjp

    def free(self, z, gradient):
        """1 where a variable may move, 0 at a bound the gradient pushes against."""
        if not self.bounded:
            return 1.0
        return np.where(((z <= self.lb) & (gradient > 0)) | ((z >= self.ub) & (gradient < 0)),
                        0.0, 1.0)

    def clipped(self, z, p):
        return p if not self.bounded else np.clip(z + p, self.lb, self.ub) - z
