"""A cloth that does not tear: the soft strain limit over every frame (:class:`StrainLimit`)."""
from __future__ import annotations

import copy

import casadi as ca
import numpy as np

from .terms import TrajectoryTerm


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
        self._scatter(scale[..., None] * d, gx)  # d value / d x_j per frame and spring
        return float(0.5 * self.weight * traj.dt * np.sum(excess ** 2))

    def _scatter(self, pull, gx) -> None:
        """Add ``pull`` (per counted frame and spring, on its end j) into ``gx``: +pull at
        j, -pull at i."""
        frames, n = pull.shape[0], gx.shape[1]
        offset = (n * np.arange(frames))[:, None]
        into_j, into_i = (self._j + offset).ravel(), (self._i + offset).ravel()
        for k in range(3):
            col = pull[..., k].ravel()
            gx[1:1 + frames, :, k] += (np.bincount(into_j, col, minlength=frames * n)
                             - np.bincount(into_i, col, minlength=frames * n)).reshape(frames, n)

    # the residual form: r = sqrt(weight dt) max(0, s - limit) per counted frame and spring
    def residual(self, traj) -> np.ndarray:
        _, _, excess = self._excess(traj.x[1:1 + self._frames(traj)])
        return np.sqrt(self.weight * traj.dt) * excess.ravel()

    def _slopes(self, traj):
        """``d r / d x_j`` per counted frame and spring (``-`` that for x_i), and the frames."""
        frames = self._frames(traj)
        d, length, excess = self._excess(traj.x[1:1 + frames])
        scale = np.sqrt(self.weight * traj.dt) * (excess > 0) / (
            self._rest * np.maximum(length, 1e-300))
        return scale[..., None] * d, frames

    def residual_jvp(self, traj, dx, dv) -> np.ndarray:
        slope, frames = self._slopes(traj)
        moved = dx[1:1 + frames, self._j] - dx[1:1 + frames, self._i]
        return np.sum(slope * moved, axis=-1).ravel()

    def residual_vjp(self, traj, w, gx, gv) -> None:
        slope, frames = self._slopes(traj)
        self._scatter(np.asarray(w, float).reshape(slope.shape[:2])[..., None] * slope, gx)

    def symbolic(self, X, V, dt, n):
        """Frame ``n``'s share, ``0.5 weight dt sum max(0, s - limit)^2`` (X: 3 x n)."""
        if not self.counts(n, dt):
            return 0
        d = X[:, self._j.tolist()] - X[:, self._i.tolist()]
        length = ca.sqrt(ca.sum1(d ** 2))
        excess = ca.fmax(length / ca.DM(self._rest).T - self.limit, 0)
        return 0.5 * self.weight * dt * ca.sumsqr(excess)

