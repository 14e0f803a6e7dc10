"""A residual map ``r``, ``phi = 0.5 |r|^2``, linearized at a point: :class:`Linearization`,
the one type every residual search works on (the residual, its Jacobian applied both ways,
``J p`` and ``J^T w``, the run it was made on and the first frame a change can move), and its
producer for a problem's objective, :func:`linearize`.

The others make the same type: multiple shooting's merit
(:func:`~..shooting.residuals.linearize_shooting`), the keyframes held over a window of late
steps (:meth:`~..finish.constraint.KeyframeConstraint.linearize`); the search in positions
will add its own.  For the objective, ``r`` stacks every term's residual (keyframe misses,
region distances, strain excess, control effort) in the problem's term order; ``J p`` is
one tangent pass along the recorded run (the integrators' exact ``step_jvp``), ``J^T w``
one backward pass with the residual cotangents as frame cotangents (the exact
``step_vjp``), then the controls' pullback.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.sparse.linalg import LinearOperator

from ...simulate import backward, tangent


class Linearization:
    """A residual map linearized at a point.

    * ``residual``: r there; :attr:`value`: ``0.5 |r|^2``;
    * :meth:`jvp` ``(p) -> J p`` and :meth:`vjp` ``(w) -> J^T w``, each counted in
      ``products``; :meth:`operator`: both as a scipy ``LinearOperator``;
    * ``size``: the variables' count; ``trajectory``: the run the products are made on
      (with its records; None where there is none of one piece);
    * ``start``: the first frame a change of the variables moves (0: the whole horizon; a
      window's first frame);
    * :meth:`release`: hand back what the run keeps for the products (its factorisations);
      no product after it.
    """

    def __init__(self, residual, jvp: Callable, vjp: Callable, *, size: int,
                 trajectory=None, start: int = 0, release: Callable | None = None):
        self.residual = residual
        self._jvp, self._vjp, self._release = jvp, vjp, release
        self.size, self.trajectory, self.start = int(size), trajectory, int(start)
        self.products = 0  # Jacobian products so far, forward and transposed

    @property
    def value(self) -> float:
        return float(0.5 * self.residual @ self.residual)

    @property
    def shape(self) -> tuple:
        return (self.residual.size, self.size)

    def jvp(self, p) -> np.ndarray:
        """``J p``: the residual's change along the variables' change ``p`` (to first order)."""
        self.products += 1
        return self._jvp(p)

    def vjp(self, w) -> np.ndarray:
        """``J^T w``: the variables' cotangent of the residual cotangent ``w``."""
        self.products += 1
        return self._vjp(w)

    def gradient(self) -> np.ndarray:
        """``J^T r``, the gradient of ``0.5 |r|^2``."""
        return self.vjp(self.residual)

    def operator(self) -> LinearOperator:
        return LinearOperator(self.shape, matvec=self.jvp, rmatvec=self.vjp, dtype=float)

    def release(self) -> None:
        if self._release is not None:
            self._release()


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


def linearize(problem, u) -> Linearization:
    """The objective's residuals of ``problem`` at the controls ``u``: one simulation with
    records, kept for the products until the linearization is released.  Exact for the
    scheme simulated (the aligned mesh keyframe's Jacobian excepted: see ``MeshKeyframe``)."""
    u = problem.controls.check(u)
    trajectory = problem.simulate(u)
    terms = TermResiduals(problem)
    pieces = terms.pieces(trajectory, u)
    ends = np.cumsum([p.size for p in pieces])

    def jvp(du):
        du = np.asarray(du, dtype=float).ravel()
        offset, forces = problem.controls.velocity_offset(du), problem.controls.external(du)
        dx, dv = tangent(problem.integrator, problem.model, trajectory,
                         np.zeros_like(problem.x0),
                         np.zeros_like(problem.v0) if offset is None else offset,
                         np.zeros_like(problem.external) if forces is None else forces)
        return np.concatenate(terms.jvp(trajectory, dx, dv, du))

    def vjp(w):
        parts = np.split(np.asarray(w, dtype=float).ravel(), ends[:-1])
        gx, gv = np.zeros_like(trajectory.x), np.zeros_like(trajectory.v)
        terms.state_vjp(trajectory, parts, gx, gv)
        g_external, g0 = backward(problem.integrator, problem.model, trajectory, gx, gv)
        return terms.control_vjp(parts, problem.controls.pullback(g_external, g0.v))

    return Linearization(np.concatenate(pieces) if pieces else np.zeros(0), jvp, vjp,
                         size=u.size, trajectory=trajectory,
                         release=lambda: problem.integrator.release(trajectory))
