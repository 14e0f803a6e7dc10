"""Keyframes on a frame's state: every particle's (or some agents') positions and
velocities (:class:`StateKeyframe`, :class:`ParticleKeyframe`) and the centre of mass
(:class:`CenterOfMassKeyframe`), each with the tolerance within which it counts as met."""
from __future__ import annotations


import casadi as ca
import numpy as np

from .keyframe_goal import KeyframeGoal
from .markers import CENTER, PARTICLES, SHAPE, VELOCITY, Marker
from .tolerances import center_tolerance, keyframe_tolerance, shortfall_phrase, tolerance_pair
from .terms import StateTerm, checked_target, particle_indices


class WeightedErrors(StateTerm):
    """A term whose value is ``0.5 (position_weight |e_x|^2 + velocity_weight |e_v|^2)`` of
    the errors its ``_errors`` gives, and whose residual is those errors, weighted."""

    def _expr(self, X, V, P, model):
        ex, ev = self._errors(X, V, P, model)
        return 0.5 * (self.position_weight * ca.sumsqr(ex)
                      + self.velocity_weight * ca.sumsqr(ev))

    def _residual_expr(self, X, V, P, model):
        ex, ev = self._errors(X, V, P, model)
        return ca.vertcat(np.sqrt(self.position_weight) * ca.vec(ex),
                          np.sqrt(self.velocity_weight) * ca.vec(ev))


class StateKeyframe(WeightedErrors):
    """Positions and/or velocities of all particles (or ``agents``) at ``frame``.

    value = 0.5 * (position_weight ||x - x*||^2 + velocity_weight ||v - v*||^2)

    ``tolerance``: when the keyframe counts as met, the rms position miss and the rms
    velocity miss over its particles: one number (positions), or a pair ``(position,
    velocity)``; None takes the default, ``inf`` checks nothing.  By default positions are
    met within 1 % of the target's extent (its bounding box's longest side; 0.01 length
    units for a single point) and velocities within the position tolerance per 0.1 s.
    """

    def __init__(self, frame: int, *, x=None, v=None, position_weight: float = 1.0,
                 velocity_weight: float | None = None, agents=None, tolerance=None):
        if x is None and v is None:
            raise ValueError("a keyframe needs a position target x, a velocity target v, or both")
        self.frame, self.x, self.v, self.agents = frame, x, v, agents
        self.tolerance = tolerance_pair(tolerance, f"{type(self).__name__}@{frame}")
        self.position_weight = float(position_weight) if x is not None else 0.0
        self.velocity_weight = (float(velocity_weight) if velocity_weight is not None
                                else (1.0 if v is not None else 0.0))
        if self.position_weight < 0 or self.velocity_weight < 0:
            raise ValueError("keyframe weights must be non-negative")

    @property
    def label(self):
        return f"{type(self).__name__}@{self.frame}"

    def _check(self, model):
        self._idx = particle_indices(self.agents, model.n, self.label)
        self._n = model.n
        shape = (self._idx.size, model.dim)
        self._x = checked_target(self.x, shape, self.label, "position")
        self._v = checked_target(self.v, shape, self.label, "velocity")
        self._tol = keyframe_tolerance(self.tolerance, self._x, self._v)

    @property
    def within(self) -> tuple:
        return self._tol

    @property
    def has_tolerance(self) -> bool:
        return any(t is not None and np.isfinite(t) for t in self._tol)

    def shortfall(self, traj) -> str | None:
        """The rms position and velocity misses beyond their tolerances, or None."""
        checks = [("rms_position_error", "rms position miss", self._tol[0]),
                  ("rms_velocity_error", "rms velocity miss", self._tol[1])]
        return shortfall_phrase(self.label, self.miss(traj), checks)

    def marker(self):
        """Every particle's target ("shape"), some particles' ("particles") or, without a
        position target, their velocities' ("velocity"), judged by the rms position and
        velocity misses against their tolerances."""
        goal = KeyframeGoal({"rms_position_error": self._tol[0],
                             "rms_velocity_error": self._tol[1]},
                            self.has_tolerance, self.miss, self.shortfall)
        if self._x is None:
            return Marker(self.label, self.frame, VELOCITY, np.zeros((0, self._v.shape[1])),
                          self._idx, goal=goal)
        if np.unique(self._idx).size == self._n:
            shape = np.empty((self._n, self._x.shape[1]))
            shape[self._idx] = self._x
            return Marker(self.label, self.frame, SHAPE, shape, goal=goal)
        return Marker(self.label, self.frame, PARTICLES, self._x, self._idx, goal=goal)

    def _params(self, model):
        zeros = np.zeros((self._idx.size, model.dim))
        xs = self._x + self.aim[0] if self._x is not None else zeros
        vs = self._v + self.aim[1] if self._v is not None else zeros
        return np.concatenate([xs.ravel(), vs.ravel()])

    def _errors(self, X, V, P, model):
        """The position and velocity errors ``(dim x particles)`` of the term's particles."""
        k = self._idx.size * model.dim
        xs = ca.reshape(P[:k], model.dim, self._idx.size)
        vs = ca.reshape(P[k:], model.dim, self._idx.size)
        idx = self._idx.tolist()
        return X[:, idx] - xs, V[:, idx] - vs


    aim = (0.0, 0.0)  # where the penalty aims, relative to the targets (see aiming)

    def aiming(self, dx=0.0, dv=0.0, weight_scale: float = 1.0,
               velocity_scale: float | None = None) -> "StateKeyframe":
        """An unbound copy (after ``bind``) whose penalty aims at the targets moved by
        ``dx``, ``dv`` (per particle) with both weights times ``weight_scale`` (the velocity
        weight times ``velocity_scale`` if given), while its
        targets, :meth:`miss` and :meth:`shortfall` stay the true ones: an augmented
        Lagrangian's keyframe (the multipliers move the aim; the goal stays put)."""
        out = self.at_frame(self.frame)
        out.agents = self._idx
        out.aim = (np.asarray(dx, dtype=float), np.asarray(dv, dtype=float))
        out.position_weight = self.position_weight * weight_scale
        out.velocity_weight = self.velocity_weight * (velocity_scale or weight_scale)
        return out

    def miss(self, traj):
        """rms (and max) distance to the targets over the keyframe's ``particles``."""
        out = {"term": self.label, "particles": int(self._idx.size)}
        if self._x is not None:
            err = np.linalg.norm(traj.x[self.frame][self._idx] - self._x, axis=1)
            out.update(rms_position_error=float(np.sqrt(np.mean(err ** 2))),
                       max_position_error=float(err.max()))
        if self._v is not None:
            err = np.linalg.norm(traj.v[self.frame][self._idx] - self._v, axis=1)
            out.update(rms_velocity_error=float(np.sqrt(np.mean(err ** 2))))
        return out


class ParticleKeyframe(StateKeyframe):
    """A keyframe on one particle or a subset (``agents`` is required)."""

    def __init__(self, frame: int, agents, **kw):
        if agents is None:
            raise ValueError("ParticleKeyframe needs the agents it constrains")
        super().__init__(frame, agents=agents, **kw)


class CenterOfMassKeyframe(WeightedErrors):
    """Mass-weighted centre of mass (and/or its velocity) of ``agents`` at ``frame``.

    ``tolerance``: the centre's distance and its velocity's miss that count as met, one
    number (position) or a pair ``(position, velocity)``; by default 0.01 length units and
    that per 0.1 s; ``inf`` checks nothing.
    """

    def __init__(self, frame: int, *, x=None, v=None, position_weight: float = 1.0,
                 velocity_weight: float | None = None, agents=None, tolerance=None):
        if x is None and v is None:
            raise ValueError("a centre-of-mass keyframe needs x, v or both")
        self.frame, self.x, self.v, self.agents = frame, x, v, agents
        self.tolerance = center_tolerance(tolerance_pair(tolerance, f"CenterOfMass@{frame}"),
                                          x is not None, v is not None)
        self.position_weight = float(position_weight) if x is not None else 0.0
        self.velocity_weight = (float(velocity_weight) if velocity_weight is not None
                                else (1.0 if v is not None else 0.0))

    @property
    def label(self):
        return f"CenterOfMass@{self.frame}"

    def _check(self, model):
        self._idx = particle_indices(self.agents, model.n, self.label)
        m = model.masses[self._idx]
        self._w = m / m.sum()
        self._x = checked_target(self.x, (model.dim,), self.label, "position")
        self._v = checked_target(self.v, (model.dim,), self.label, "velocity")

    def _params(self, model):
        z = np.zeros(model.dim)
        return np.concatenate([z if self._x is None else self._x, z if self._v is None else self._v])

    def _errors(self, X, V, P, model):
        """The centre's position and velocity errors."""
        idx, w = self._idx.tolist(), ca.DM(self._w)
        cx, cv = ca.mtimes(X[:, idx], w), ca.mtimes(V[:, idx], w)
        return cx - P[:model.dim], cv - P[model.dim:]


    def marker(self):
        """The centre's target ("center"; without one, "velocity" of its ``particles``),
        judged by its position and velocity misses."""
        goal = KeyframeGoal({"position_error": self.tolerance[0],
                             "velocity_error": self.tolerance[1]},
                            self.has_tolerance, self.miss, self.shortfall)
        if self._x is None:
            return Marker(self.label, self.frame, VELOCITY, np.zeros((0, self._v.size)),
                          self._idx, goal=goal)
        return Marker(self.label, self.frame, CENTER, self._x, goal=goal)

    def center(self, traj, frame=None):
        return self._w @ traj.x[self.frame if frame is None else frame][self._idx]

    @property
    def within(self) -> tuple:
        return self.tolerance

    @property
    def has_tolerance(self) -> bool:
        return any(t is not None and np.isfinite(t) for t in self.tolerance)

    def shortfall(self, traj) -> str | None:
        """The centre's position and velocity misses beyond their tolerances, or None."""
        checks = [("position_error", "position miss", self.tolerance[0]),
                  ("velocity_error", "velocity miss", self.tolerance[1])]
        return shortfall_phrase(self.label, self.miss(traj), checks)

    def miss(self, traj):
        out = {"term": self.label}
        if self._x is not None:
            out["position_error"] = float(np.linalg.norm(self.center(traj) - self._x))
        if self._v is not None:
            cv = self._w @ traj.v[self.frame][self._idx]
            out["velocity_error"] = float(np.linalg.norm(cv - self._v))
        return out


