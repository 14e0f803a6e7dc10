"""The objective and its kinds of term: a sum (:class:`Objective`) of state terms (one
frame's positions and velocities), control terms and trajectory terms (every frame).

A state term is written once as a CasADi expression of that frame's positions and velocities
(``dim x n`` matrices) and a parameter vector; its value and its state derivative come from
the same compiled function, and the exact CasADi route embeds the same expression in the
unrolled simulation.  Weights multiply squared errors: ``0.5 * weight * ||error||^2`` (the
paper's ``W_n`` is ``sqrt(weight)``).
"""
from __future__ import annotations

import copy

import casadi as ca
import numpy as np

from .markers import Marker


class Objective:
    """A sum of terms.  ``term_a + term_b`` builds one; so does ``Objective([...])``."""

    def __init__(self, terms=()):
        self.terms = []
        for t in terms:
            self.terms.extend(t.terms if isinstance(t, Objective) else [t])
        for t in self.terms:
            if not isinstance(t, (StateTerm, ControlTerm, TrajectoryTerm)):
                raise TypeError(f"not an objective term: {t!r}")

    def __add__(self, other):
        return Objective([self, other])

    __radd__ = __add__

    @property
    def state_terms(self):
        return [t for t in self.terms if isinstance(t, StateTerm)]

    @property
    def control_terms(self):
        return [t for t in self.terms if isinstance(t, ControlTerm)]

    @property
    def trajectory_terms(self):
        return [t for t in self.terms if isinstance(t, TrajectoryTerm)]

    def bound(self, model, steps: int) -> "Objective":
        """The objective of the state and trajectory terms bound to ``model`` over ``steps``
        (checked and compiled copies, see :meth:`StateTerm.bind`); the terms given stay as
        they were."""
        return Objective([t.bind(model, steps) if isinstance(t, (StateTerm, TrajectoryTerm))
                          else t for t in self.terms])

    def markers(self) -> list:
        """What the bound keyframe terms show (:class:`~.markers.Marker`), term by term."""
        return [m for t in self.state_terms if (m := t.marker()) is not None]

    def retimed(self, frame_of) -> "Objective":
        """The same objective with every state term moved to frame ``frame_of(term)`` (for a
        problem resampled in time).  Control terms are shared: they are time integrals
        written with the problem's dt (see :class:`Smoothness`), so they need no re-timing."""
        return Objective([t.at_frame(frame_of(t)) if isinstance(t, StateTerm) else t
                          for t in self.terms])


class _Addable:
    def __add__(self, other):
        return Objective([self, other])

    def __radd__(self, other):
        return Objective([other, self]) if other != 0 else Objective([self])


class StateTerm(_Addable):
    """A term that looks at the state of one frame.

    A term is written as the user gives it; :meth:`bind` returns a copy checked against a
    system and compiled, which remembers the term it was made from (:attr:`unbound`)."""

    frame: int

    @property
    def unbound(self) -> "StateTerm":
        """The term as it was given (itself, if it is not a bound copy)."""
        return self.__dict__.get("_unbound", self)

    def at_frame(self, frame: int) -> "StateTerm":
        """An unbound copy of this term, with the same targets and weights, at ``frame``."""
        out = copy.copy(self.unbound)
        out.frame = frame
        return out

    def bind(self, model, steps: int) -> "StateTerm":
        """A copy of the term checked against the system and compiled; the term itself stays
        as it was."""
        if not (isinstance(self.frame, (int, np.integer)) and 0 <= self.frame <= steps):
            raise ValueError(f"{self.label}: keyframe frame {self.frame} is outside 0..{steps}; "
                             "pick a frame within the horizon or raise 'steps'")
        out = copy.copy(self.unbound)
        out._unbound = self.unbound
        out._check(model)
        out._compile(model)
        return out

    def _compile(self, model) -> None:
        """Compile the bound term's value and state derivatives for ``model``."""
        self._model = model
        X = ca.SX.sym("X", model.dim, model.n)
        V = ca.SX.sym("V", model.dim, model.n)
        self._p = self._params(model)
        P = ca.SX.sym("P", self._p.size)
        val = self._expr(X, V, P, model)
        name = "term_" + "".join(c if c.isalnum() else "_" for c in self.label)
        self._fn = ca.Function(name, [X, V, P], [val, ca.gradient(val, X), ca.gradient(val, V)])
        self._sym = ca.Function(name + "_value", [X, V, P], [val])

    def marker(self) -> Marker | None:
        """What this (bound) term shows at its frame, or None if it has nothing to show."""
        return None

    def accumulate(self, traj, gx, gv) -> float:
        """Add this term's state derivative into ``gx, gv``; return its value."""
        n = self.frame
        val, dx, dv = self._fn(traj.x[n].T, traj.v[n].T, self._p)
        gx[n] += np.asarray(dx).T
        gv[n] += np.asarray(dv).T
        return float(val)

    def value(self, traj) -> float:
        return float(self._sym(traj.x[self.frame].T, traj.v[self.frame].T, self._p))

    def symbolic(self, X, V):
        return self._sym(X, V, self._p)

    # -- the residual form: value = 0.5 |r|^2 (a Gauss-Newton search's view) ----------------
    def residual(self, traj) -> np.ndarray:
        """The (bound) term's residual r at its frame, with value = 0.5 |r|^2."""
        n = self.frame
        return np.asarray(self._residual_fns()[0](traj.x[n].T, traj.v[n].T, self._p)).ravel()

    def residual_jvp(self, traj, dx, dv) -> np.ndarray:
        """``J_r`` times the frame tangents ``dx, dv`` ``(steps + 1, n, dim)``."""
        n = self.frame
        out = self._residual_fns()[1](traj.x[n].T, traj.v[n].T, self._p, dx[n].T, dv[n].T)
        return np.asarray(out).ravel()

    def residual_vjp(self, traj, w, gx, gv) -> None:
        """Add ``J_r^T w`` (the residual cotangent ``w``) into the frame cotangents ``gx, gv``."""
        n = self.frame
        ax, av = self._residual_fns()[2](traj.x[n].T, traj.v[n].T, self._p, w)
        gx[n] += np.asarray(ax).T
        gv[n] += np.asarray(av).T

    def _residual_fns(self):
        """The residual, its forward and its transposed product, compiled at first use."""
        fns = self.__dict__.get("_residual_compiled")
        if fns is None:
            model = self._model
            X, V = ca.SX.sym("X", model.dim, model.n), ca.SX.sym("V", model.dim, model.n)
            dX, dV = ca.SX.sym("dX", model.dim, model.n), ca.SX.sym("dV", model.dim, model.n)
            P = ca.SX.sym("P", self._p.size)
            r = ca.vec(self._residual_expr(X, V, P, model))
            w = ca.SX.sym("w", r.numel())
            XV, dXV = ca.vertcat(ca.vec(X), ca.vec(V)), ca.vertcat(ca.vec(dX), ca.vec(dV))
            back = ca.jtimes(r, XV, w, True)
            k = model.dim * model.n
            fns = self._residual_compiled = (
                ca.Function("r", [X, V, P], [r]),
                ca.Function("r_jvp", [X, V, P, dX, dV], [ca.jtimes(r, XV, dXV)]),
                ca.Function("r_vjp", [X, V, P, w], [ca.reshape(back[:k], model.dim, model.n),
                                                    ca.reshape(back[k:], model.dim, model.n)]))
        return fns

    def _residual_expr(self, X, V, P, model):
        """The residual as a CasADi expression, ``0.5 sumsqr(r) == _expr``."""
        raise NotImplementedError(no_residual(self))

    # subclasses
    label = "term"

    def _check(self, model):
        pass

    def _params(self, model) -> np.ndarray:
        return np.zeros(0)

    def _expr(self, X, V, P, model):
        raise NotImplementedError

    def miss(self, traj) -> dict:
        """How far the trajectory is from this keyframe, in the units a user thinks in."""
        raise NotImplementedError

    def shortfall(self, traj) -> str | None:
        """What this (bound) keyframe misses beyond its tolerance in ``traj``, as a phrase
        naming the term, each miss and its tolerance; None when every tolerance holds (or
        the term declares none).  A search's goal is met when no term falls short."""
        return None

    has_tolerance = False  # whether shortfall can fail: the term is part of the goal
    within = None  # (position, velocity) tolerance of a bound state or centre keyframe

    @property
    def particles(self) -> np.ndarray:
        """Indices of the particles this term looks at (after ``bind``)."""
        return self._idx

    @property
    def position_target(self):
        """The bound position target (``None`` if the term has none)."""
        return getattr(self, "_x", None)

    @property
    def velocity_target(self):
        """The bound velocity target (``None`` if the term has none)."""
        return getattr(self, "_v", None)


def particle_indices(agents, n, label):
    if agents is None:
        return np.arange(n)
    idx = np.atleast_1d(np.asarray(agents))
    if idx.dtype.kind not in "iu" or idx.size == 0:
        raise ValueError(f"{label}: agents must be a non-empty list of particle indices")
    if idx.min() < 0 or idx.max() >= n:
        raise ValueError(f"{label}: particle index out of range 0..{n - 1}: {idx.tolist()}")
    return idx.astype(np.intp)


def checked_target(value, shape, label, what):
    """A float target of ``shape`` (a single row broadcasts to every particle)."""
    if value is None:
        return None
    try:
        arr = np.array(np.broadcast_to(np.asarray(value, dtype=float), shape))
    except ValueError:
        raise ValueError(f"{label}: {what} target must have shape {shape}, "
                         f"got {np.shape(value)}") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{label}: {what} target contains NaN or inf")
    return arr


class ControlTerm(_Addable):
    """A term on the controls only.  Its residual form (for a Gauss-Newton search):
    ``residual(u, controls, dt)`` with value = 0.5 |r|^2, ``residual_jvp(du, controls, dt)``
    and ``residual_vjp(w, controls, dt)``, the products with its Jacobian and transpose."""

    def residual(self, u, controls, dt) -> np.ndarray:
        raise NotImplementedError(no_residual(self))


class TrajectoryTerm(_Addable):
    """A term on every frame of the motion (not a keyframe): ``value(traj)``,
    ``accumulate(traj, gx, gv)`` (its derivative added into every frame) and
    ``symbolic(X, V, dt, n)`` for frame n of the unrolled CasADi route."""

    def bind(self, model, steps: int) -> "TrajectoryTerm":
        """The term checked against the system (a copy where it keeps what it found)."""
        return self

    def residual(self, traj) -> np.ndarray:
        """The residual over every frame, value = 0.5 |r|^2; with ``residual_jvp(traj, dx,
        dv)`` and ``residual_vjp(traj, w, gx, gv)`` as for a :class:`StateTerm`."""
        raise NotImplementedError(no_residual(self))


def no_residual(term) -> str:
    """Why a term without a residual form cannot be searched by Gauss-Newton."""
    return (f"{getattr(term, 'label', type(term).__name__)} has no residual form (value = "
            f"0.5 |r|^2), which a Gauss-Newton search needs: give {type(term).__name__} "
            "one (a state term: _residual_expr), or search with method='lbfgsb'")

