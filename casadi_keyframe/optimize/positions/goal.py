"""The goal in positions: every keyframe within its tolerance, as constraints on the unknowns
of a :class:`~.transcription.Transcription`.

A keyframe's miss is a norm of errors that are linear in the positions (a particle's position
at its frame, its velocity as the difference of two frames over dt, a centre of mass), so
each tolerance is the quadratic constraint

    c(z) = |R z + r0|^2 / count - (margin tolerance)^2 <= 0,

its gradient ``2 R^T r / count`` and its Hessian ``2 R^T R / count`` exact and constant.
``margin`` (< 1) keeps a result inside its tolerance, not on its edge.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...objectives import CenterOfMassKeyframe, StateKeyframe
from .transcription import TranscriptionError

MARGIN = 0.9  # a keyframe is held within this share of its tolerance


@dataclass(frozen=True)
class Constraint:
    """``|R z + r0|^2 / count <= bound``: the rms miss (or the centre's distance) of one
    keyframe's positions or velocities; ``label`` names it in messages."""

    label: str
    R: sp.csr_matrix
    r0: np.ndarray
    count: int
    bound: float

    def residual(self, z) -> np.ndarray:
        return self.R @ z + self.r0

    def value(self, z) -> float:
        r = self.residual(z)
        return float(r @ r) / self.count - self.bound

    def gradient(self, z) -> np.ndarray:
        return (2.0 / self.count) * (self.R.T @ self.residual(z))

    def hessian(self) -> sp.csr_matrix:
        return ((2.0 / self.count) * (self.R.T @ self.R)).tocsr()

    def miss(self, z) -> float:
        """The rms miss (or distance) at ``z``."""
        r = self.residual(z)
        return float(np.sqrt(r @ r / self.count))


def goal_constraints(transcription, margin: float = MARGIN) -> list[Constraint]:
    """One :class:`Constraint` per checked tolerance of the problem's keyframes (position
    and velocity apart); TranscriptionError for a keyframe whose miss is not a norm of
    positions (an aligned mesh keyframe, a region), naming what to do instead."""
    problem = transcription.problem
    out = []
    for term in problem.objective_terms.state_terms:
        if not term.has_tolerance:
            continue
        if getattr(term, "align", False) or not isinstance(
                term, (StateKeyframe, CenterOfMassKeyframe)):
            raise TranscriptionError(
                f"{problem.name}: the transcription holds keyframes whose miss is a distance "
                f"of positions or velocities; {term.label} is not one "
                f"({'its target is aligned by a rigid motion first' if getattr(term, 'align', False) else type(term).__name__}): "
                "give align=False, or solve with method='lbfgsb'")
        out += _constraints(transcription, term, margin)
    if not out:
        raise TranscriptionError(f"{problem.name}: no keyframe declares a tolerance: the "
                                 "transcription minimises the effort under the goal, and "
                                 "there is none; give the keyframes tolerances")
    return out


def _constraints(tr, term, margin) -> list[Constraint]:
    """The position and the velocity constraint of ``term`` (where it checks them)."""
    position_tol, velocity_tol = term.within
    centre = isinstance(term, CenterOfMassKeyframe)
    idx = term._idx
    counted = np.ones(idx.size, bool) if centre else np.asarray(
        getattr(term, "counted", np.ones(idx.size, bool)), bool)
    weights = term._w if centre else None
    out = []
    for kind, tol, target in (("x", position_tol, term._x), ("v", velocity_tol, term._v)):
        if tol is None or not np.isfinite(tol) or target is None:
            continue
        frames = [(term.frame, 1.0)] if kind == "x" else [(term.frame, 1 / tr.dt),
                                                          (term.frame - 1, -1 / tr.dt)]
        if kind == "v" and term.frame == 0:
            continue  # the start's velocity is given: nothing to hold
        R, r0 = _linear_map(tr, frames, idx[counted] if not centre else idx, weights)
        t = target if centre else target[counted]
        count = 1 if centre else int(counted.sum())
        out.append(Constraint(f"{term.label} {'position' if kind == 'x' else 'velocity'}",
                              R, r0 - np.ravel(t), count, (margin * tol) ** 2))
    return out


def _linear_map(tr, frames, particles, weights=None):
    """``(R, r0)`` with ``R z + r0`` the stacked positions (or their weighted sum: a centre)
    of ``particles`` at the combination ``sum c_k x_{frame_k}`` of ``frames``."""
    rows, cols, vals = [], [], []
    r0 = np.zeros((1 if weights is not None else particles.size, 3))
    column = -np.ones(3 * tr.n, np.intp)
    column[tr.free_flat] = np.arange(tr.nf)
    for frame, coef in frames:
        x = tr.base[frame]
        for a, p in enumerate(particles):
            w = coef * (1.0 if weights is None else weights[a])
            row = 0 if weights is not None else a
            for d in range(3):
                c = column[3 * p + d]
                if frame >= 1 and c >= 0:
                    rows.append(3 * row + d), cols.append((frame - 1) * tr.nf + c), vals.append(w)
                else:  # the start, or a prescribed component: a constant
                    r0[row, d] += w * x[p, d]
    R = sp.csr_matrix((vals, (rows, cols)), shape=(r0.size, tr.size))
    return R, r0.ravel()
