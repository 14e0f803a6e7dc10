"""Keyframe objective terms; they add up with ``+``.

A state term is active at one frame and is written once as a CasADi expression of that
frame's positions and velocities (``dim x n`` matrices) and a parameter vector.  Its value
and its derivative with respect to the state come from the same compiled function, and the
exact gradient route embeds the same expression in the unrolled simulation.  A control term
(:class:`Smoothness`) depends on the controls only.

Weights multiply squared errors: ``0.5 * weight * ||error||^2`` (the paper's ``W_n`` is
``sqrt(weight)``).
"""
from __future__ import annotations

import copy

import casadi as ca
import numpy as np

from .shapes import Shape
from .tolerances import center_tolerance, keyframe_tolerance, shortfall_phrase, tolerance_pair
from .views import Marker


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
        """What the bound keyframe terms show (:class:`~.views.Marker`), term by term."""
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


def _agents(agents, n, label):
    if agents is None:
        return np.arange(n)
    idx = np.atleast_1d(np.asarray(agents))
    if idx.dtype.kind not in "iu" or idx.size == 0:
        raise ValueError(f"{label}: agents must be a non-empty list of particle indices")
    if idx.min() < 0 or idx.max() >= n:
        raise ValueError(f"{label}: particle index out of range 0..{n - 1}: {idx.tolist()}")
    return idx.astype(np.intp)


def _target(value, shape, label, what):
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


class StateKeyframe(StateTerm):
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
        self._idx = _agents(self.agents, model.n, self.label)
        self._n = model.n
        shape = (self._idx.size, model.dim)
        self._x = _target(self.x, shape, self.label, "position")
        self._v = _target(self.v, shape, self.label, "velocity")
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
        """Every particle's target ("shape") or some particles' ("particles")."""
        if self._x is None:
            return None
        if np.unique(self._idx).size == self._n:
            shape = np.empty((self._n, self._x.shape[1]))
            shape[self._idx] = self._x
            return Marker(self.label, self.frame, "shape", shape)
        return Marker(self.label, self.frame, "particles", self._x, self._idx)

    def _params(self, model):
        zeros = np.zeros((self._idx.size, model.dim))
        xs = self._x + self.aim[0] if self._x is not None else zeros
        vs = self._v + self.aim[1] if self._v is not None else zeros
        return np.concatenate([xs.ravel(), vs.ravel()])

    def _expr(self, X, V, P, model):
        k = self._idx.size * model.dim
        xs = ca.reshape(P[:k], model.dim, self._idx.size)
        vs = ca.reshape(P[k:], model.dim, self._idx.size)
        idx = self._idx.tolist()
        return 0.5 * (self.position_weight * ca.sumsqr(X[:, idx] - xs)
                      + self.velocity_weight * ca.sumsqr(V[:, idx] - vs))

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


class CenterOfMassKeyframe(StateTerm):
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
        self._idx = _agents(self.agents, model.n, self.label)
        m = model.masses[self._idx]
        self._w = m / m.sum()
        self._x = _target(self.x, (model.dim,), self.label, "position")
        self._v = _target(self.v, (model.dim,), self.label, "velocity")

    def _params(self, model):
        z = np.zeros(model.dim)
        return np.concatenate([z if self._x is None else self._x, z if self._v is None else self._v])

    def _expr(self, X, V, P, model):
        idx, w = self._idx.tolist(), ca.DM(self._w)
        cx, cv = ca.mtimes(X[:, idx], w), ca.mtimes(V[:, idx], w)
        d = model.dim
        return 0.5 * (self.position_weight * ca.sumsqr(cx - P[:d])
                      + self.velocity_weight * ca.sumsqr(cv - P[d:]))

    def marker(self):
        return None if self._x is None else Marker(self.label, self.frame, "center", self._x)

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


class RegionTarget(StateTerm):
    """Agents should be inside ``shape`` at ``frame``.

    value = 0.5 * weight * sum_i max(0, sd(x_i) + margin)^2: the squared distance outside
    the shape shrunk by ``margin``, summed over the agents outside it (the paper's box term).
    ``fill``: the fraction of the agents inside the shape that counts as met (default 1.0,
    every one; 0 checks nothing).
    """

    def __init__(self, frame: int, shape: Shape, *, weight: float = 1.0, margin: float = 0.0,
                 agents=None, fill: float = 1.0):
        if not isinstance(shape, Shape):
            raise TypeError("RegionTarget needs a Shape (Box, Disc, Polygon, square, cross)")
        if weight < 0 or margin < 0:
            raise ValueError("RegionTarget weight and margin must be non-negative")
        if isinstance(fill, bool) or not (isinstance(fill, (int, float)) and 0 <= fill <= 1):
            raise ValueError(f"RegionTarget: fill is the fraction of the agents inside the "
                             f"shape that counts as met, in [0, 1], got {fill!r}")
        self.fill = float(fill)
        self.frame, self.shape, self.weight, self.margin, self.agents = (
            frame, shape, float(weight), float(margin), agents)

    @property
    def label(self):
        return f"Region{type(self.shape).__name__}@{self.frame}"

    def _check(self, model):
        self._idx = _agents(self.agents, model.n, self.label)

    def _expr(self, X, V, P, model):
        sd = self.shape.sd_function.map(self._idx.size)(X[:2, self._idx.tolist()])
        return 0.5 * self.weight * ca.sumsqr(ca.fmax(sd + self.margin, 0))

    def marker(self):
        return Marker(self.label, self.frame, "outline", self.shape.outline(), self._idx)

    @property
    def has_tolerance(self) -> bool:
        return self.fill > 0

    def shortfall(self, traj) -> str | None:
        """The fraction of the agents inside the shape, when below ``fill``; else None."""
        inside = self.miss(traj)["fraction_inside"]
        if self.fill <= 0 or inside >= self.fill:
            return None
        return f"{self.label}: {inside:.1%} of the agents inside (goal {self.fill:.0%})"

    def miss(self, traj):
        sd = self.shape.signed_distance(traj.x[self.frame][self._idx])
        return {"term": self.label, "fraction_inside": float(np.mean(sd <= 0)),
                "max_distance_outside": float(max(sd.max(), 0.0))}


class ControlTerm(_Addable):
    """A term on the controls only."""


class Smoothness(ControlTerm):
    """The paper's ``alpha ||C_n u||^2``, plus an optional penalty on changes between steps.

    For per-step forces u_n:  ``0.5 alpha dt sum_n |u_n|^2 + 0.5 temporal / dt sum_n
    |u_{n+1} - u_n|^2``: Riemann sums of ``0.5 alpha int |u|^2 dt`` and ``0.5 temporal int
    |du/dt|^2 dt``, so a weight means the same physical cost at any dt (a force held constant
    has the same alpha-cost on a grid twice as fine; a jump between steps costs more on it).
    For initial velocities: ``0.5 alpha |u|^2``.
    """

    label = "Smoothness"

    def __init__(self, alpha: float, *, temporal: float = 0.0):
        if alpha < 0 or temporal < 0:
            raise ValueError("Smoothness weights must be non-negative")
        self.alpha, self.temporal = float(alpha), float(temporal)

    def symbolic(self, U, controls, dt):
        """The term as a CasADi expression of the flat control vector ``U``."""
        blocks = controls.step_blocks(U)  # (block, steps) matrix, or None for no steps
        if blocks is None:
            return 0.5 * self.alpha * ca.sumsqr(U)
        val = 0.5 * self.alpha * dt * ca.sumsqr(blocks)
        if self.temporal and blocks.shape[1] > 1:
            val += 0.5 * self.temporal / dt * ca.sumsqr(blocks[:, 1:] - blocks[:, :-1])
        return val


class TrajectoryTerm(_Addable):
    """A term on every frame of the motion (not a keyframe): ``value(traj)``,
    ``accumulate(traj, gx, gv)`` (its derivative added into every frame) and
    ``symbolic(X, V, dt, n)`` for frame n of the unrolled CasADi route."""

    def bind(self, model, steps: int) -> "TrajectoryTerm":
        """The term checked against the system (a copy where it keeps what it found)."""
        return self


class StrainLimit(TrajectoryTerm):
    """A cloth that does not tear: ``0.5 weight dt sum_n sum_springs max(0, s - limit)^2``
    over frames 1..N (or those up to time ``until``, seconds), with ``s = |x_j - x_i| /
    rest`` a spring's stretch.  Zero while every spring stays below ``limit`` times its rest
    length, and C^1 (its derivative is the hinge's), so it limits strain softly and leaves
    motions within the limit alone; a Riemann sum of a time integral, so a weight means the
    same at any dt.  Its value counts in a result's ``keyframe_error`` (the objective less
    the control cost)."""

    label = "StrainLimit"

    def __init__(self, limit: float = 1.1, weight: float = 1e3, until: float | None = None):
        if not (np.isfinite(limit) and limit >= 1) or not (np.isfinite(weight) and weight >= 0):
            raise ValueError(f"StrainLimit needs limit >= 1 and weight >= 0, got {limit}, "
                             f"{weight}")
        if until is not None and not (np.isfinite(until) and until > 0):
            raise ValueError(f"StrainLimit: until is a time in seconds > 0 (None: every "
                             f"frame), got {until!r}")
        self.limit, self.weight, self.until = float(limit), float(weight), until

    def counts(self, n: int, dt: float) -> bool:
        """Whether frame ``n`` (of step ``dt``) is one the limit holds on."""
        return n >= 1 and (self.until is None or n * dt <= self.until * (1 + 1e-9))

    def _frames(self, traj) -> int:
        """How many frames from frame 1 on count."""
        return sum(self.counts(n, traj.dt) for n in range(1, traj.x.shape[0]))

    def bind(self, model, steps: int) -> "StrainLimit":
        springs = getattr(model, "springs", None)
        if springs is None:
            raise ValueError("StrainLimit needs a cloth (a model with springs)")
        out = copy.copy(self)
        out._i, out._j, out._rest = springs.i, springs.j, springs.rest
        return out

    def _excess(self, x):
        d = x[..., self._j, :] - x[..., self._i, :]
        length = np.linalg.norm(d, axis=-1)
        return d, length, np.maximum(length / self._rest - self.limit, 0.0)

    def value(self, traj) -> float:
        _, _, excess = self._excess(traj.x[1:1 + self._frames(traj)])
        return float(0.5 * self.weight * traj.dt * np.sum(excess ** 2))

    def accumulate(self, traj, gx, gv) -> float:
        d, length, excess = self._excess(traj.x[1:1 + self._frames(traj)])
        scale = self.weight * traj.dt * excess / (self._rest * np.maximum(length, 1e-300))
        pull = scale[..., None] * d  # d value / d x_j per frame and spring
        frames, n = pull.shape[0], traj.x.shape[1]
        offset = (n * np.arange(frames))[:, None]
        into_j, into_i = (self._j + offset).ravel(), (self._i + offset).ravel()
        for k in range(3):
            col = pull[..., k].ravel()
            gx[1:1 + frames, :, k] += (np.bincount(into_j, col, minlength=frames * n)
                             - np.bincount(into_i, col, minlength=frames * n)).reshape(frames, n)
        return float(0.5 * self.weight * traj.dt * np.sum(excess ** 2))

    def symbolic(self, X, V, dt, n):
        """Frame ``n``'s share, ``0.5 weight dt sum max(0, s - limit)^2`` (X: 3 x n)."""
        if not self.counts(n, dt):
            return 0
        d = X[:, self._j.tolist()] - X[:, self._i.tolist()]
        length = ca.sqrt(ca.sum1(d ** 2))
        excess = ca.fmax(length / ca.DM(self._rest).T - self.limit, 0)
        return 0.5 * self.weight * dt * ca.sumsqr(excess)
