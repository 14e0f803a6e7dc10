"""The method of multipliers, once, for every equality a search holds hard: keyframes in
:func:`~.augmented_lagrangian.solve_augmented`'s rounds, and multiple shooting's
continuity defects (:mod:`.shooting`).

A constraint block ``c_b = 0`` (a keyframe's position miss, a segment's defect) enters the
objective as ``0.5 w_b |c_b + lambda_b / w_b|^2`` (equal to ``lambda_b . c_b + 0.5 w_b
|c_b|^2`` up to a constant): the penalty ``w_b`` aims past the target by the shift
``lambda_b / w_b``.  After each inner search ``lambda_b += w_b c_b`` (the first-order
update: the shift moves by the miss that is left) and the weights grow by ``growth``,
either every time (a fixed schedule: the keyframe rounds), or as Conn, Gould and Toint's
LANCELOT does: where the miss fell below ``shrink`` times its last size the multiplier
moves, elsewhere the weight grows and the multiplier stays (moving it by a miss the inner
search could not shrink only winds it up).
"""
from __future__ import annotations

import numpy as np

from ..objectives import Objective, StateKeyframe


class Multipliers:
    """Multipliers and penalty weights of named constraint blocks.

    ``weights``: each block's starting penalty weight (a number); ``growth`` >= 1 the
    factor a weight grows by; ``always``: move every multiplier and grow every weight at
    each update (a schedule), rather than the LANCELOT rule (see the module).
    """

    def __init__(self, weights: dict, *, growth: float = 1.0, always: bool = True,
                 shrink: float = 0.25):
        if not (np.isfinite(growth) and growth >= 1):
            raise ValueError(f"the weight growth must be >= 1 (1: multipliers alone), got "
                             f"{growth}")
        self.weights = {b: float(w) for b, w in weights.items()}
        self.lam = {b: 0.0 for b in weights}
        self.growth, self.always, self.shrink = float(growth), bool(always), float(shrink)
        self.last = {b: np.inf for b in weights}  # each block's miss norm at the last update
        self.updates = 0

    def shift(self, block) -> np.ndarray | float:
        """Where block's penalty aims, relative to its target: ``lambda / w``."""
        return self.lam[block] / self.weights[block]

    def value(self, block, c) -> float:
        """``0.5 w |c + lambda / w|^2``: the block's part of the objective at residual c."""
        return 0.5 * self.weights[block] * float(np.sum((c + self.shift(block)) ** 2))

    def gradient(self, block, c):
        """d value / d c = ``w c + lambda``."""
        return self.weights[block] * c + self.lam[block]

    def update(self, residuals: dict, *, multipliers: bool = True) -> None:
        """After an inner search that ended at these ``residuals`` (block -> c): ``lambda +=
        w c`` (unless ``multipliers`` is False: the penalty schedule alone), then grow the
        weights (every one, or those whose miss did not shrink enough)."""
        for b, c in residuals.items():
            c = np.asarray(c, dtype=float)
            size = float(np.linalg.norm(c))
            progress = self.always or size <= self.shrink * self.last[b] or not np.isfinite(
                self.last[b])
            if multipliers and progress:
                self.lam[b] = self.lam[b] + self.weights[b] * c
            if self.always or not progress:
                self.weights[b] *= self.growth
            self.last[b] = size
        self.updates += 1

    def state(self, prefix: str = "") -> dict:
        """Plain arrays (for a checkpoint): ``{prefix}lam:{b}``, ``{prefix}weight:{b}`` per
        block (b as a string) and ``{prefix}updates``."""
        out = {f"{prefix}updates": np.array(self.updates)}
        for b in self.weights:
            out[f"{prefix}lam:{b}"] = np.asarray(self.lam[b], dtype=float)
            out[f"{prefix}weight:{b}"] = np.array(self.weights[b])
        return out

    def restore(self, state: dict, prefix: str = "") -> bool:
        """Take the multipliers and weights :meth:`state` wrote, where every block has its
        entries (True), else leave them (False: a run of another problem)."""
        keys = [(f"{prefix}lam:{b}", f"{prefix}weight:{b}") for b in self.weights]
        if f"{prefix}updates" not in state or any(k not in state for pair in keys for k in pair):
            return False
        for b, (lam, weight) in zip(self.weights, keys):
            self.lam[b] = np.asarray(state[lam], dtype=float)
            self.weights[b] = float(state[weight])
        self.updates = int(state[f"{prefix}updates"])
        return True


class KeyframeMultipliers:
    """The :class:`~.multipliers.Multipliers` of a problem's StateKeyframes (one block per
    position and per velocity target, keyed ``x3``, ``v3`` by the term's place among the
    objective's terms) and the problem whose keyframes aim by them."""

    def __init__(self, problem, growth: float, always: bool = True):
        self.base = problem
        terms = problem.objective_terms.terms
        self.terms = {i: t for i, t in enumerate(terms) if isinstance(t, StateKeyframe)}
        if not self.terms:
            raise ValueError(f"{problem.name}: no StateKeyframe term to hold hard; an "
                             "augmented Lagrangian needs a state target (positions and/or "
                             "velocities)")
        self.start = {f"{kind}{i}": w for i, t in self.terms.items()
                      for kind, target, w in (("x", t.position_target, t.position_weight),
                                              ("v", t.velocity_target, t.velocity_weight))
                      if target is not None and w > 0}
        self.mult = Multipliers(self.start, growth=growth, always=always)
        self.round = 0

    @property
    def scale(self) -> float:
        """The keyframe weights' factor this round (the largest, where they differ)."""
        return max(self.mult.weights[b] / w for b, w in self.start.items())

    def problem(self):
        """The base problem with each keyframe aiming past its target by the shift (the base
        problem itself before any update)."""
        if not self.mult.updates:
            return self.base
        terms = []
        for i, t in enumerate(self.base.objective_terms.terms):
            if i in self.terms:
                dx, dv = (-self.mult.shift(f"{k}{i}") if f"{k}{i}" in self.start else 0.0
                          for k in "xv")
                sx, sv = (self.mult.weights[f"{k}{i}"] / self.start[f"{k}{i}"]
                          if f"{k}{i}" in self.start else None for k in "xv")
                t = t.aiming(dx, dv, sx or sv, sv)
            terms.append(t)
        return self.base.with_objective(Objective(terms))

    def update(self, traj, multipliers: bool = True) -> None:
        """After a round that ended at ``traj``: the multipliers move by the misses left
        and the weights grow."""
        residuals = {}
        for i, t in self.terms.items():
            for kind, target, states in (("x", t.position_target, traj.x),
                                         ("v", t.velocity_target, traj.v)):
                if f"{kind}{i}" in self.start:
                    residuals[f"{kind}{i}"] = states[t.frame][t.particles] - target
        self.mult.update(residuals, multipliers=multipliers)
        self.round += 1

    def checkpoint(self, checkpoint, k: int):
        """``checkpoint`` (or None) writing round ``k`` and the multipliers with the controls."""
        if checkpoint is None:
            return None
        state = {key: value.tolist() for key, value in self.mult.state("rounds_").items()}
        return checkpoint.with_meta(generation=k, rounds_round=k, **state)

    def resume(self, meta: dict | None) -> int:
        """Take the multipliers a checkpoint's ``meta`` carries; the round to start at."""
        if not meta or "rounds_round" not in meta or not self.mult.restore(meta, "rounds_"):
            return 0
        self.round = int(meta["rounds_round"])
        return self.round
