"""How the control vector u acts on the system (the paper's C_n).

Every control starts at zero, meaning the passive simulation.  ``u`` is a flat float64
vector; the classes below say how it maps to per-step external forces or to a change of
the initial velocities, how gradients flow back, and give the same map symbolically for the
exact CasADi route.
"""
from __future__ import annotations

import copy

import casadi as ca
import numpy as np
import scipy.sparse as sp



def _numbers(u, what: str) -> np.ndarray:
    """``u`` as a float64 array if it holds real numbers only, else a TypeError that says
    what it holds (``what`` says what it should be)."""
    if u is None or isinstance(u, (str, bytes)):
        raise TypeError(f"{what}, got {u!r}")
    try:
        arr = np.asarray(u)
    except (ValueError, TypeError):  # ragged nested lists
        raise TypeError(f"{what}, got a ragged {type(u).__name__}") from None
    kind = arr.dtype.kind
    if kind == "c":
        raise TypeError(f"{what}, got complex numbers: pass the real part (u.real) if the "
                        "imaginary part is meant to be zero")
    if kind == "b":
        raise TypeError(f"{what}, got booleans")
    if kind == "O":
        odd = next((v for v in arr.ravel() if not _is_real(v)), None)
        if odd is not None or any(v is None for v in arr.ravel()):
            raise TypeError(f"{what}, got Python objects that are not numbers (e.g. {odd!r})")
        return arr.astype(float)
    if kind not in "iuf":
        raise TypeError(f"{what}, got {'text' if kind in 'US' else 'values'} of dtype "
                        f"{arr.dtype}")
    return arr.astype(float, copy=False)


def _is_real(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def resample_steps(values, steps: int) -> np.ndarray:
    """Per-step values ``(old_steps, ...)`` carried to ``steps`` equal steps of the same horizon.

    The values are read as a piecewise-constant function of time (value n held over step n)
    and each new step gets that function's mean over its interval.  So the integral over any
    interval the two grids share (the impulse of a force) is kept exactly; refining by a whole
    factor repeats each value, coarsening by one averages each group.  Entries whose weight is
    zero never touch the result, so infinite bounds stay infinite.
    """
    values = np.asarray(values, dtype=float)
    old = values.shape[0]
    if not (isinstance(steps, (int, np.integer)) and steps >= 1):
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if steps == old:
        return values.copy()
    # In units of 1 / (old * steps) of the horizon, old step i is [i*steps, (i+1)*steps) and
    # new step j is [j*old, (j+1)*old): the overlaps are whole numbers, the weights exact.
    rows, cols, weights = [], [], []
    for j in range(steps):
        lo, hi = j * old, (j + 1) * old
        for i in range(lo // steps, min(-(-hi // steps), old)):
            overlap = min(hi, (i + 1) * steps) - max(lo, i * steps)
            if overlap > 0:
                rows.append(j), cols.append(i), weights.append(overlap / old)
    remap = sp.csr_matrix((weights, (rows, cols)), shape=(steps, old))
    return (remap @ values.reshape(old, -1)).reshape((steps,) + values.shape[1:])


class Controls:
    """Base: ``bind`` to a system, then map ``u`` to forces / initial-velocity offsets.

    ``smoothing`` (metres, per-particle controls of a mesh) and ``time_smoothing``
    (seconds, step forces) change only the geometry the optimizer searches in, not the
    objective: the optimizer builds its metric from them
    (:func:`casadi_keyframe.optimize.metrics.search_metric`).  They exclude bounds."""

    def __init__(self, agents=None, *, lower=None, upper=None, smoothing: float | None = None,
                 time_smoothing: float | None = None):
        self.agents, self.lower, self.upper = agents, lower, upper
        for name, value in (("smoothing", smoothing), ("time_smoothing", time_smoothing)):
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive length (None for none), got "
                                 f"{value!r}")
        if (smoothing or time_smoothing) and (lower is not None or upper is not None):
            raise ValueError("smoothing changes the search's variables, so it cannot keep "
                             "bounds on u: give either bounds or smoothing")
        self.smoothing, self.time_smoothing = smoothing, time_smoothing

    def bind(self, n: int, dim: int, steps: int) -> None:
        if self.agents is None:
            self.idx = np.arange(n)
        else:
            self.idx = np.unique(np.atleast_1d(np.asarray(self.agents)))
            if self.idx.dtype.kind not in "iu" or self.idx.size == 0:
                raise ValueError("controlled agents must be a non-empty list of indices")
            if self.idx.min() < 0 or self.idx.max() >= n:
                raise ValueError(f"controlled agent index out of range 0..{n - 1}")
        self.n, self.dim, self.steps = n, dim, steps
        self.bounds()  # validate early
        if self.time_smoothing and len(self.block_shape) != 3:
            raise ValueError(f"time_smoothing needs controls per step; {type(self).__name__} "
                             "has none: use smoothing (over the mesh) alone")

    @property
    def block_shape(self) -> tuple:
        raise NotImplementedError

    @property
    def size(self) -> int:
        return int(np.prod(self.block_shape))

    def zeros(self) -> np.ndarray:
        return np.zeros(self.size)

    def for_steps(self, steps: int) -> "Controls":
        """An unbound copy of these controls for the same system over ``steps`` steps (for a
        problem resampled in time); bounds given per control entry are carried like ``u``."""
        return copy.copy(self)

    def resample(self, u, steps: int) -> np.ndarray:
        """The controls ``u`` (bound to ``self.steps``) carried to ``steps`` steps of the same
        horizon, so that they act the same way in time."""
        raise NotImplementedError(
            f"{type(self).__name__} does not say how to carry its controls to another time "
            "step: define resample(u, steps) (and for_steps if its bounds are per step)")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds on u (``-inf``/``inf`` where unbounded)."""
        lb = np.broadcast_to(-np.inf if self.lower is None else np.asarray(self.lower, float),
                             (self.size,)).copy()
        ub = np.broadcast_to(np.inf if self.upper is None else np.asarray(self.upper, float),
                             (self.size,)).copy()
        if np.any(np.isnan(lb)) or np.any(np.isnan(ub)) or np.any(lb > ub):
            raise ValueError("control bounds must satisfy lower <= upper and contain no NaN")
        if np.any(lb > 0) or np.any(ub < 0):
            raise ValueError("control bounds must contain zero (the passive simulation)")
        return lb, ub

    def check(self, u) -> np.ndarray:
        """``u`` as a flat float64 vector of :attr:`size` finite real numbers; a TypeError
        for anything that is not real numbers (None, text, complex, booleans), a ValueError
        for a wrong length or NaN and inf."""
        what = (f"controls must be a flat vector of {self.size} real numbers "
                f"({' x '.join(map(str, self.block_shape))})")
        arr = _numbers(u, what)
        if arr.shape != (self.size,):
            raise ValueError(f"{what}, got shape {arr.shape}"
                             + (f" ({arr.size} values)" if arr.ndim > 1 else ""))
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"controls contain NaN or inf (at {np.size(np.flatnonzero(~np.isfinite(arr)))} "
                             "entries)")
        return arr

    # numeric map and its transpose
    def external(self, u) -> np.ndarray | None:
        """Per-step control forces ``(steps, n, dim)``, or None."""
        return None

    def velocity_offset(self, u) -> np.ndarray | None:
        """Change of the initial velocities ``(n, dim)``, or None."""
        return None

    def pullback(self, g_external, g_v0) -> np.ndarray:
        """d phi / d u from d phi / d(external forces) and d phi / d v0."""
        raise NotImplementedError

    # symbolic map
    def symbolic(self, U):
        """``(list of per-step dim x n forces or None, dim x n velocity offset or None)``."""
        raise NotImplementedError

    def step_blocks(self, U):
        """U as a ``(k*dim, steps)`` matrix, one column per step; None if not per-step."""
        return None

    def _selection(self) -> ca.DM:
        sel = np.zeros((self.idx.size, self.n))
        sel[np.arange(self.idx.size), self.idx] = 1.0
        return ca.sparsify(ca.DM(sel))


class StepForces(Controls):
    """One force per controlled particle per step (the paper's flocking and cloth controls).

    ``u`` holds forces in newtons, not impulses: ``u[n]`` is held over step n, from ``n dt``
    to ``(n + 1) dt``, and so gives the impulse ``u[n] dt``.  The same force-versus-time on
    another grid therefore needs no rescaling: :meth:`resample` maps it piecewise constant
    in time (see :func:`resample_steps`), keeping the impulse over every shared interval.
    """

    label = "per-step forces"

    @property
    def block_shape(self):
        return (self.steps, self.idx.size, self.dim)

    def for_steps(self, steps):
        out = copy.copy(self)
        for name in ("lower", "upper"):
            bound = getattr(self, name)
            if bound is not None and np.size(bound) == self.size and self.size > 1:
                setattr(out, name, self.resample(np.ravel(bound), steps))
        return out

    def resample(self, u, steps):
        blocks = np.asarray(u, dtype=float).reshape(self.block_shape)
        return resample_steps(blocks, steps).ravel()

    def external(self, u):
        """The control forces ``(steps, n, dim)`` in newtons, one per step (zero where not
        controlled); the integrator applies ``external[n]`` over step n."""
        out = np.zeros((self.steps, self.n, self.dim))
        out[:, self.idx] = u.reshape(self.block_shape)
        return out

    def pullback(self, g_external, g_v0):
        return np.ascontiguousarray(g_external[:, self.idx]).ravel()

    def step_blocks(self, U):
        return ca.reshape(U, self.idx.size * self.dim, self.steps)

    def symbolic(self, U):
        blocks = self.step_blocks(U)
        sel = self._selection()
        k = self.idx.size
        forces = [ca.mtimes(ca.reshape(blocks[:, s], self.dim, k), sel) for s in range(self.steps)]
        return forces, None


class InitialVelocity(Controls):
    """Only the initial velocities of the controlled particles (fig. 5: the cloth toss)."""

    label = "initial velocities"

    @property
    def block_shape(self):
        return (self.idx.size, self.dim)

    def resample(self, u, steps):
        """Initial velocities do not depend on the time step: ``u`` unchanged (a copy)."""
        return np.array(u, dtype=float)

    def velocity_offset(self, u):
        out = np.zeros((self.n, self.dim))
        out[self.idx] = u.reshape(self.block_shape)
        return out

    def pullback(self, g_external, g_v0):
        return np.ascontiguousarray(g_v0[self.idx]).ravel()

    def symbolic(self, U):
        return None, ca.mtimes(ca.reshape(U, self.dim, self.idx.size), self._selection())
