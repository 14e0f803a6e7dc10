"""The control effort: the paper's ``alpha ||C_n u||^2`` and a penalty on changes between
steps (:class:`Smoothness`)."""
from __future__ import annotations


import casadi as ca
import numpy as np

from .terms import ControlTerm


class Smoothness(ControlTerm):
    """The paper's ``alpha ||C_n u||^2``, plus an optional penalty on changes between steps.

    For per-step forces u_n:  ``0.5 alpha dt sum_n |u_n|^2 + 0.5 temporal / dt sum_n
    |u_{n+1} - u_n|^2``: Riemann sums of ``0.5 alpha int |u|^2 dt`` and ``0.5 temporal int
    |du/dt|^2 dt``, so a weight means the same physical cost at any dt (a force held constant
    has the same alpha-cost on a grid twice as fine; a jump between steps costs more on it).
    For initial velocities: ``0.5 alpha |u|^2``.

    ``weights`` (one per controlled particle, the paper's ``C_n``): each particle's share
    of both sums is weighed by its own (:meth:`in_accelerations` makes the cost one of
    accelerations).  None weighs every particle by 1.
    """

    label = "Smoothness"

    def __init__(self, alpha: float, *, temporal: float = 0.0, weights=None):
        if alpha < 0 or temporal < 0:
            raise ValueError("Smoothness: alpha and temporal must be non-negative")
        self.alpha, self.temporal = float(alpha), float(temporal)
        self.weights = None
        if weights is not None:
            self.weights = np.asarray(weights, dtype=float).ravel()
            if not np.all(np.isfinite(self.weights)) or np.any(self.weights <= 0):
                raise ValueError("Smoothness weights: give one positive finite number per "
                                 "controlled particle")

    @classmethod
    def in_accelerations(cls, alpha: float, masses, *, temporal: float = 0.0) -> "Smoothness":
        """The cost of the control accelerations ``u / m`` (``masses``: the controlled
        particles', in their order), each particle's force weighed by ``(mean mass / m)^2``:
        a particle of the mean mass costs what it costs unweighted.  Unweighted, a particle
        a sixth as heavy (a mesh's corner) is thirty-six times cheaper to accelerate, and a
        least-effort search jerks the light ones."""
        masses = np.asarray(masses, dtype=float).ravel()
        if masses.size == 0 or np.any(masses <= 0):
            raise ValueError("Smoothness.in_accelerations: give the controlled particles' "
                             "masses, every one positive")
        return cls(alpha, temporal=temporal, weights=(masses.mean() / masses) ** 2)

    def _roots_of_weights(self, controls) -> np.ndarray | None:
        """``sqrt(weight)`` of every entry of one step's block (None: unweighted)."""
        if self.weights is None:
            return None
        if self.weights.size != controls.idx.size:
            raise ValueError(f"Smoothness weights: {self.weights.size} given, the controls "
                             f"move {controls.idx.size} particles; give one per controlled "
                             "particle, in the controls' order")
        return np.repeat(np.sqrt(self.weights), controls.block_shape[-1])

    def _scaled(self, u, controls) -> np.ndarray:
        """The flat controls ``u`` with every entry times its particle's ``sqrt(weight)``:
        the weighted term is the unweighted one of these."""
        root = self._roots_of_weights(controls)
        u = np.asarray(u, float)
        return u if root is None else u * np.tile(root, controls.size // root.size)

    def symbolic(self, U, controls, dt):
        """The term as a CasADi expression of the flat control vector ``U``."""
        root = self._roots_of_weights(controls)
        blocks = controls.step_blocks(U)  # (block, steps) matrix, or None for no steps
        if blocks is None:
            return 0.5 * self.alpha * ca.sumsqr(U if root is None else ca.DM(root) * U)
        if root is not None:
            blocks = ca.DM(root) * blocks  # each row (a particle's component) weighed
        val = 0.5 * self.alpha * dt * ca.sumsqr(blocks)
        if self.temporal and blocks.shape[1] > 1:
            val += 0.5 * self.temporal / dt * ca.sumsqr(blocks[:, 1:] - blocks[:, :-1])
        return val

    # the residual form: sqrt(alpha dt) u_n and sqrt(temporal / dt) (u_{n+1} - u_n), or
    # sqrt(alpha) u for initial velocities; linear, so its Jacobian is the map itself
    def _roots(self, controls, dt):
        """The residual's two factors, and the steps (None: controls without steps)."""
        if len(controls.block_shape) != 3:
            return np.sqrt(self.alpha), 0.0, None
        steps = controls.block_shape[0]
        return (np.sqrt(self.alpha * dt), np.sqrt(self.temporal / dt) if steps > 1 else 0.0,
                steps)

    def residual(self, u, controls, dt) -> np.ndarray:
        root, change, steps = self._roots(controls, dt)
        u = self._scaled(u, controls)
        if not change:
            return root * u
        blocks = u.reshape(steps, -1)
        return np.concatenate([root * u, change * (blocks[1:] - blocks[:-1]).ravel()])

    residual_jvp = residual  # linear in u

    def residual_vjp(self, w, controls, dt) -> np.ndarray:
        root, change, steps = self._roots(controls, dt)
        w = np.asarray(w, float)
        size = controls.size
        out = root * w[:size]
        if change:
            diff = change * w[size:].reshape(steps - 1, -1)
            blocks = out.reshape(steps, -1)  # a view: adds into out
            blocks[1:] += diff
            blocks[:-1] -= diff
        return self._scaled(out, controls)
