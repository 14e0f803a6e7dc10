"""A keyframe given as a mesh: the cloth at a frame should take the shape of a target mesh
(a file a DCC wrote, a sculpted shape key), vertex by vertex.

The target must be the cloth's own mesh in another shape: the same number of vertices, in
the same order, joined by the same faces (checked when the term is bound to the cloth, with
a message saying which differs).  Optionally the match is made after the best rigid motion
of the target onto the cloth (``align=True``): then only the shape counts, not where the
shape is or how it is turned.
"""
from __future__ import annotations

import os

import casadi as ca
import numpy as np

from ..geometry import best_rigid_motion
from ..meshes import Mesh, read_mesh
from ..models.base import Surface
from .keyframes import StateKeyframe


class MeshKeyframe(StateKeyframe):
    """Every particle at ``frame`` on its vertex of the ``target`` mesh.

    ``target``: a mesh file (OBJ, PLY, USD: :func:`~casadi_keyframe.meshes.read_mesh`), a
    :class:`~casadi_keyframe.meshes.Mesh`, or ``(n, 3)`` positions.  ``weight``: the
    position weight; ``vertex_weights``: optional non-negative weights per vertex (a vertex
    of weight 0 is left free and not counted in the miss); ``v``: an optional velocity
    target, as for :class:`~casadi_keyframe.objectives.StateKeyframe`.

    value = 0.5 weight sum_i w_i |x_i - x*_i|^2 (+ the velocity part), or with ``align``

    value = 0.5 weight min over rotations R and translations t of sum_i w_i |x_i - (R x*_i + t)|^2

    whose gradient is ``weight w_i (x_i - (R x*_i + t))`` at the best (R, t) (the envelope
    theorem: the minimiser's own change does not count).  The aligned value has no CasADi
    expression (the best rotation comes from an SVD), so the "casadi" gradient route refuses
    it; the "adjoint" route and finite differences take it.
    """

    def __init__(self, frame: int, target, *, weight: float = 1.0, vertex_weights=None,
                 align: bool = False, v=None, velocity_weight: float | None = None,
                 tolerance=None):
        self.mesh = _mesh_of(target)
        positions = self.mesh.vertices if self.mesh is not None else np.asarray(target, float)
        if positions.ndim != 2 or positions.shape[1] != 3:
            raise ValueError(f"MeshKeyframe@{frame}: the target must be a mesh file, a Mesh or "
                             f"(n, 3) positions, got an array of shape {positions.shape}")
        if align and v is not None:
            raise ValueError(f"MeshKeyframe@{frame}: align=True compares shapes only; give no "
                             f"velocity target v (or align=False)")
        super().__init__(frame, x=positions, v=v, position_weight=weight,
                         velocity_weight=velocity_weight, tolerance=tolerance)
        self.align = bool(align)
        self.vertex_weights = None
        if vertex_weights is not None:
            w = np.asarray(vertex_weights, float).ravel()
            if w.shape != (len(positions),) or not np.all(np.isfinite(w)) or np.any(w < 0):
                raise ValueError(f"MeshKeyframe@{frame}: vertex_weights must be {len(positions)} "
                                 f"non-negative numbers, one per target vertex")
            if not np.any(w > 0):
                raise ValueError(f"MeshKeyframe@{frame}: every vertex weight is 0: nothing to aim for")
            self.vertex_weights = w

    @property
    def label(self):
        return f"MeshKeyframe@{self.frame}"

    @property
    def source(self) -> str:
        """The target's file, for messages ("positions" when it was given as an array)."""
        return self.mesh.label() if self.mesh is not None else "positions"

    def _check(self, model):
        if self.agents is None and len(self.x) != model.n:
            raise ValueError(f"{self.label}: the target {self.source} has {len(self.x)} "
                             f"vertices, the cloth {model.n}; a target must be the cloth's own "
                             f"mesh in another shape (same vertices in the same order, same "
                             f"faces)")
        if (self.mesh is not None and isinstance(model, Surface)
                and not self.mesh.same_topology(model.faces)):
            raise ValueError(f"{self.label}: the target {self.source} has the cloth's "
                             f"{model.n} vertices but other faces; export the target from the "
                             f"cloth's mesh (moving vertices only, no faces added, removed or "
                             f"re-ordered corners)")
        super()._check(model)
        self._w = np.ones(len(self.x)) if self.vertex_weights is None else self.vertex_weights

    def _expr(self, X, V, P, model):
        if self.vertex_weights is None:
            return super()._expr(X, V, P, model)
        ex, ev = self._errors(X, V, P, model)
        w = ca.DM(self._w).T
        return 0.5 * (self.position_weight * ca.sum2(w * ca.sum1(ex ** 2))
                      + self.velocity_weight * ca.sumsqr(ev))

    def _residual_expr(self, X, V, P, model):
        if self.vertex_weights is None:
            return super()._residual_expr(X, V, P, model)
        ex, ev = self._errors(X, V, P, model)
        root = ca.DM(np.sqrt(self.position_weight * self._w)).T
        return ca.vertcat(ca.vec(ex * ca.repmat(root, model.dim, 1)),
                          np.sqrt(self.velocity_weight) * ca.vec(ev))

    # -- the aligned match: value and gradient in numpy, at the best rigid motion ----------
    def aligned_target(self, x) -> np.ndarray:
        """The target carried by the rigid motion that best fits it to the positions ``x``
        (``(n, 3)``, the cloth's particles) with the vertex weights."""
        R, t = best_rigid_motion(self._x, x[self._idx], self._w)
        return self._x @ R.T + t

    def value(self, traj) -> float:
        if not self.align:
            return super().value(traj)
        x = traj.x[self.frame]
        err = x[self._idx] - self.aligned_target(x)
        return float(0.5 * self.position_weight * np.sum(self._w[:, None] * err ** 2))

    def accumulate(self, traj, gx, gv) -> float:
        if not self.align:
            return super().accumulate(traj, gx, gv)
        x = traj.x[self.frame]
        err = x[self._idx] - self.aligned_target(x)
        gx[self.frame][self._idx] += self.position_weight * self._w[:, None] * err
        return float(0.5 * self.position_weight * np.sum(self._w[:, None] * err ** 2))

    # the aligned residual r_i = sqrt(weight w_i) (x_i - (R x*_i + t)): its Jacobian for a
    # Gauss-Newton search is APPROXIMATE, the projection off the rigid motions' directions
    # (Kaufman's variable projection), exact where r = 0; J^T r is the exact gradient
    def residual(self, traj):
        if not self.align:
            return super().residual(traj)
        x = traj.x[self.frame]
        return (self._root()[:, None] * (x[self._idx] - self.aligned_target(x))).ravel()

    def residual_jvp(self, traj, dx, dv):
        if not self.align:
            return super().residual_jvp(traj, dx, dv)
        return self._off_rigid(traj, (self._root()[:, None] * dx[self.frame][self._idx]).ravel())

    def residual_vjp(self, traj, w, gx, gv):
        if not self.align:
            return super().residual_vjp(traj, w, gx, gv)
        back = self._off_rigid(traj, np.asarray(w, float)).reshape(-1, 3)
        gx[self.frame][self._idx] += self._root()[:, None] * back

    def _root(self):
        return np.sqrt(self.position_weight * self._w)

    @property
    def counted(self) -> np.ndarray:
        """Which of its particles its miss counts (vertex weight not 0; after ``bind``)."""
        return self._w > 0

    def _off_rigid(self, traj, r):
        """``r`` less its part along the rigid motions of the aligned target (weighted)."""
        y, root = self.aligned_target(traj.x[self.frame]), self._root()
        basis = []
        for k in range(3):
            axis = np.zeros(3)
            axis[k] = 1.0
            basis += [root[:, None] * axis, root[:, None] * np.cross(axis, y)]
        q, sv, _ = np.linalg.svd(np.stack([b.ravel() for b in basis], axis=1),
                                 full_matrices=False)
        q = q[:, sv > 1e-12 * sv[0]]  # a target on a line turns about it freely
        return r - q @ (q.T @ r)

    def symbolic(self, X, V):
        if self.align:
            raise ValueError(f"{self.label}: align=True has no CasADi expression (the best "
                             f"rotation is an SVD); use the 'adjoint' or 'fd' gradient route")
        return super().symbolic(X, V)

    def aiming(self, dx=0.0, dv=0.0, weight_scale: float = 1.0, velocity_scale=None):
        if self.align:
            raise ValueError(f"{self.label}: an aligned target cannot be moved by a miss (its "
                             f"frame turns with the cloth); use align=False for hard keyframes")
        return super().aiming(dx, dv, weight_scale, velocity_scale)

    def miss(self, traj):
        """rms and max distance to the target (after the best rigid motion with ``align``)
        over the particles whose weight is not 0."""
        x = traj.x[self.frame]
        target = self.aligned_target(x) if self.align else self._x
        counted = self._w > 0
        err = np.linalg.norm(x[self._idx] - target, axis=1)[counted]
        out = {"term": self.label, "particles": int(counted.sum()),
               "rms_position_error": float(np.sqrt(np.mean(err ** 2))),
               "max_position_error": float(err.max())}
        if self._v is not None:
            verr = np.linalg.norm(traj.v[self.frame][self._idx] - self._v, axis=1)[counted]
            out["rms_velocity_error"] = float(np.sqrt(np.mean(verr ** 2)))
        return out


def _mesh_of(target) -> Mesh | None:
    if isinstance(target, Mesh):
        return target
    if isinstance(target, (str, os.PathLike)):
        return read_mesh(target)
    return None
