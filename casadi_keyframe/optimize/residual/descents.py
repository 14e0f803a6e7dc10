"""Descents: how a residual search turns a :class:`~.linearization.Linearization` into a step
of a given size (as optimistix pairs a descent with a step-size search, :mod:`.steps`).

* :class:`SteihaugPath`: the Gauss-Newton model's conjugate-gradient path, cut at a trust
  radius (the Gauss-Newton method's);
* :class:`Landing`: the least change that lands the linearized residual, scaled (the
  finish's landing steps);
* :class:`Projected`: a quadratic cost's Newton step projected onto the changes that leave
  the linearized residual where it is, damped (the finish's effort steps).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla


class SteihaugPath:
    """CG's path on the Gauss-Newton model ``0.5 |r + J p|^2`` from p = 0, up to the trust
    ``radius`` (None: unbounded), ``maxiter`` iterations or the model's gradient below
    ``rtol`` times its start; :meth:`step` gives the step at any radius up to that one.

    ``jvp(d) -> J d``, ``vjp(s) -> J^T s``, ``gradient`` ``J^T r``.  CG's iterates grow in
    norm (Steihaug), so the path crosses each radius once.  With ``plane`` a step the radius
    cuts is the better (by the model) of the path's point there and the best point within
    the radius in the plane of the gradient and the path's end (scipy's ``trf`` subspace):
    on a stiff model the path's first segment, steepest descent, is a poor step."""

    def __init__(self, jvp, vjp, r, gradient, radius, maxiter, rtol, plane=True):
        self.segments = []  # (start p, direction d, its longest step, |s|^2, s.q, |q|^2)
        self.r, self.gradient, self.plane = np.asarray(r, dtype=float), gradient, plane
        s, z = self.r.copy(), -np.asarray(gradient, dtype=float)
        gamma = first = z @ z
        p, d = np.zeros_like(z), z.copy()
        for _ in range(maxiter if first > 0 else 0):
            q = jvp(d)
            if not self.segments:
                self.j_gradient = -q  # d = -gradient at first
            qq = q @ q
            if not qq > 0:
                break
            alpha = gamma / qq
            self.segments.append((p, d, alpha, s @ s, s @ q, qq))
            p, s = p + alpha * d, s + alpha * q
            if radius is not None and np.linalg.norm(p) >= radius:
                break
            z = -vjp(s)
            gamma, last = z @ z, gamma
            if gamma <= rtol ** 2 * first:
                break
            d = z + (gamma / last) * d
        self.end = (p, s)  # the path's last point and its model residual r + J p

    def step(self, radius):
        """``(p, model value at p)``: the path's end, or its best step within ``radius``."""
        if not self.segments:
            return None, None
        p_end, s_end = self.end
        if radius is None or np.linalg.norm(p_end) <= radius:
            return p_end, 0.5 * s_end @ s_end
        for p, d, alpha, ss, sq, qq in self.segments:
            if np.linalg.norm(p + alpha * d) > radius:
                alpha = _to_sphere(p, d, radius)
                break
        cut, model = p + alpha * d, 0.5 * (ss + 2 * alpha * sq + alpha * alpha * qq)
        if self.plane:
            flat, flat_model = self._in_plane(radius)
            if flat_model < model:
                return flat, flat_model
        return cut, model

    def _in_plane(self, radius):
        """The model's best point within ``radius`` in the span of the gradient and the
        path's end, from products already made (``J g``, ``J p_end = s_end - r``)."""
        p_end, s_end = self.end
        basis, tri = np.linalg.qr(np.stack([self.gradient, p_end], axis=1))
        keep = np.abs(np.diag(tri)) > 1e-12 * np.abs(tri[0, 0])
        basis, tri = basis[:, keep], tri[np.ix_(keep, keep)]
        images = np.stack([self.j_gradient, s_end - self.r], axis=1)[:, keep]
        j_basis = np.linalg.solve(tri.T, images.T).T  # J basis = images tri^-1
        x = trust_region_small(j_basis.T @ j_basis, j_basis.T @ self.r, radius)
        residual = self.r + j_basis @ x
        return basis @ x, 0.5 * residual @ residual


def trust_region_small(B, c, radius) -> np.ndarray:
    """argmin ``0.5 x^T B x + c^T x`` over ``|x| <= radius`` for a small symmetric positive
    semi-definite B (its eigenvectors, and the secular equation solved by bisection)."""
    w, V = np.linalg.eigh(B)
    ct = V.T @ c

    def length(lam):
        return np.linalg.norm(ct / (w + lam))

    if w.min() > 0 and length(0.0) <= radius:
        return -V @ (ct / w)
    lo = max(0.0, -w.min()) + 1e-300
    hi = lo + np.linalg.norm(c) / radius + np.abs(w).max() + 1.0
    if not length(lo) > radius:  # the hard case: along the flattest direction to the edge
        x = -ct / np.where(w + lo > 0, w + lo, np.inf)
        x[np.argmin(w)] += np.sqrt(max(radius ** 2 - x @ x, 0.0))
        return V @ x
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if length(mid) > radius else (lo, mid)
    return -V @ (ct / (w + hi))


def _to_sphere(p, d, radius) -> float:
    """The tau >= 0 with ``|p + tau d| = radius`` (``|p| <= radius``)."""
    a, b, c = d @ d, 2 * p @ d, p @ p - radius * radius
    return float((-b + np.sqrt(max(b * b - 4 * a * c, 0.0))) / (2 * a))


class _Window:
    """The products of ``lin`` (a linearization whose variables are all the controls) on the
    variables ``cols`` only."""

    def __init__(self, lin, cols):
        self.lin, self.cols = lin, cols

    def jvp(self, d_window) -> np.ndarray:
        du = np.zeros(self.lin.size)
        du[self.cols] = d_window
        return self.lin.jvp(du)

    def vjp(self, y) -> np.ndarray:
        return self.lin.vjp(y)[self.cols]


class Landing:
    """The change of the variables ``cols`` that lands the linearized residual of ``lin``, or
    comes closest: the least squares solution of ``J d = -r`` of least norm in the metric of
    ``diagonal`` (LSMR, at most ``iterations`` iterations to the relative tolerance ``tol``;
    a miss the variables cannot steer is left, not chased with ever larger changes).  A step
    of size ``s`` is ``s d``."""

    def __init__(self, lin, cols, diagonal, iterations: int, tol: float):
        window = _Window(lin, cols)
        scale = 1.0 / np.sqrt(diagonal)
        J = spla.LinearOperator((lin.residual.size, cols.size), dtype=float,
                                matvec=lambda z: window.jvp(scale * z),
                                rmatvec=lambda w: scale * window.vjp(w))
        z = spla.lsmr(J, -lin.residual, atol=tol, btol=tol, maxiter=iterations)[0]
        self.direction = scale * z

    def step(self, size: float) -> np.ndarray:
        return size * self.direction


class Projected:
    """The Newton step of a quadratic cost on the variables ``cols`` (its Hessian factored
    there, ``factors``; its gradient there, ``gradient``), projected onto the changes that
    leave the linearized residual of ``lin`` where it is: conjugate gradients on ``(J Q^-1
    J^T) y = J Q^-1 g`` (at most ``iterations``, to ``rtol`` relative and ``atol``
    absolute), an iteration one product each way.  A step damped by ``s`` is
    ``d / (1 + s)``."""

    def __init__(self, lin, cols, factors, gradient, iterations: int, rtol: float,
                 atol: float):
        window = _Window(lin, cols)
        m = lin.residual.size
        A = spla.LinearOperator((m, m), dtype=float,
                                matvec=lambda y: window.jvp(factors.solve(window.vjp(y))))
        gi = factors.solve(gradient)
        y, _ = spla.cg(A, window.jvp(gi), rtol=rtol, atol=atol, maxiter=iterations)
        self.direction = -gi + factors.solve(window.vjp(y))

    def step(self, damping: float) -> np.ndarray:
        return self.direction / (1.0 + damping)
