"""Smooth metrics for per-particle controls: the geometry the optimizer searches in.

Per-particle controls of a stiff cloth have a near-null space: force or velocity patterns
that vary from particle to particle are absorbed by the springs within a step, and the finer
the mesh the more of them there are, so a plain gradient search slows and its trial steps
tear the sheet.  With ``smoothing`` the optimizer searches over z with ``u = S z``,

    S = (I + tau^2 L_t)^-1  (x)  (I + l^2 L_x)^-1  (x)  I_dim,

``L_x`` the graph Laplacian of the mesh's edges among the controlled particles (weights
``1 / |edge|^2`` at rest, so the length ``l`` is in metres and the metric does not change
with resolution) and ``L_t`` the Laplacian of the time steps (weights ``1 / dt^2``, ``tau``
in seconds; step forces only).  S is symmetric positive definite and keeps constants, so
the objective is the same function of u; only the search's steps (``S^2`` times the
gradient in u) are smoothed over about ``l`` and ``tau``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..models.base import Surface
from ..models.topology import mesh_edges


def search_metric(problem):
    """The :class:`SmoothingMetric` a search of ``problem`` runs in, from its controls'
    ``smoothing`` (metres, over the mesh) and ``time_smoothing`` (seconds, over the steps);
    None without either.  Space smoothing needs a mesh (a model with a surface)."""
    controls, model = problem.controls, problem.model
    space = time = None
    if controls.smoothing:
        if not isinstance(model, Surface):
            raise ValueError("smoothing over space needs a mesh (a cloth); for a flock use "
                             "time_smoothing")
        laplacian = mesh_laplacian(model.faces, model.rest_positions, controls.idx)
        space = controls.smoothing ** 2 * laplacian
    if controls.time_smoothing and len(controls.block_shape) == 3:
        time = controls.time_smoothing ** 2 * path_laplacian(controls.steps, problem.dt)
    if space is None and time is None:
        return None
    return SmoothingMetric(controls.block_shape, space, time)


def mesh_laplacian(faces, positions, idx) -> sp.csc_matrix:
    """The graph Laplacian of the mesh edges between the particles ``idx`` (their order),
    weights ``1 / |edge|^2`` at ``positions``."""
    edges = mesh_edges(faces)
    where = np.full(len(positions), -1)
    where[idx] = np.arange(len(idx))
    a, b = where[edges[:, 0]], where[edges[:, 1]]
    keep = (a >= 0) & (b >= 0)
    a, b, edges = a[keep], b[keep], edges[keep]
    length2 = np.sum((positions[edges[:, 0]] - positions[edges[:, 1]]) ** 2, axis=1)
    w = 1.0 / length2
    k = len(idx)
    W = sp.coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(k, k)).tocsc()
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsc()


def path_laplacian(steps: int, dt: float) -> sp.csc_matrix:
    """The Laplacian of ``steps`` values in a row, weights ``1 / dt^2``."""
    if steps < 2:
        return sp.csc_matrix((steps, steps))
    ones = np.ones(steps - 1) / dt ** 2
    W = sp.diags([ones, ones], [-1, 1], shape=(steps, steps))
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsc()


class SmoothingMetric:
    """``u = S z`` for controls of ``shape`` ``(steps, k, dim)`` or ``(k, dim)``: S the
    product of ``(I + l^2 L_x)^-1`` over the particle axis (``space``: the Laplacian scaled,
    or None) and ``(I + tau^2 L_t)^-1`` over the step axis (``time``, or None)."""

    def __init__(self, shape: tuple, space=None, time=None):
        self.shape = tuple(shape)
        self.axes = []  # (axis, A = I + scaled Laplacian, its LU factors)
        for axis, scaled in ((len(shape) - 2, space), (0, time)):
            if scaled is not None and scaled.nnz:
                A = (sp.identity(scaled.shape[0], format="csc") + scaled).tocsc()
                self.axes.append((axis, A, spla.splu(A)))

    def _along(self, values, axis, apply):
        moved = np.moveaxis(values, axis, 0)
        flat = moved.reshape(moved.shape[0], -1)
        return np.moveaxis(apply(flat).reshape(moved.shape), 0, axis)

    def smooth(self, z) -> np.ndarray:
        """``S z`` (also ``S^T g``: S is symmetric), flat in, flat out."""
        values = np.asarray(z, dtype=float).reshape(self.shape)
        for axis, _, lu in self.axes:
            values = self._along(values, axis, lu.solve)
        return values.ravel()

    def unsmooth(self, u) -> np.ndarray:
        """``S^-1 u``: the z of given controls."""
        values = np.asarray(u, dtype=float).reshape(self.shape)
        for axis, A, _ in self.axes:
            values = self._along(values, axis, A.dot)
        return values.ravel()
