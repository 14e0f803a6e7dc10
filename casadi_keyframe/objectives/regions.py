"""Region targets: particles inside a shape (squared distance outside it, summed over the
particles outside), met when enough of them are inside."""
from __future__ import annotations


import casadi as ca
import numpy as np

from ..shapes import Shape
from .keyframe_goal import KeyframeGoal
from .markers import OUTLINE, Marker
from .terms import StateTerm, particle_indices


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
        self._idx = particle_indices(self.agents, model.n, self.label)

    def _outside(self, X):
        """Each agent's distance outside the shape shrunk by the margin (0 inside)."""
        sd = self.shape.sd_function.map(self._idx.size)(X[:2, self._idx.tolist()])
        return ca.fmax(sd + self.margin, 0)

    def _expr(self, X, V, P, model):
        return 0.5 * self.weight * ca.sumsqr(self._outside(X))

    def _residual_expr(self, X, V, P, model):
        return np.sqrt(self.weight) * ca.vec(self._outside(X))

    def marker(self):
        """The region's outline, judged by the fraction of the agents inside it."""
        goal = KeyframeGoal({"fraction_inside": self.fill}, self.has_tolerance, self.miss,
                            self.shortfall)
        return Marker(self.label, self.frame, OUTLINE, self.shape.outline(), self._idx,
                      goal=goal)

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


