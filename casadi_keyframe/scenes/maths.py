"""Small maths the scenes share: rotations and C^2 bumps and soft limits that keep animations
smooth (the smoothstep ramp is :mod:`..objectives.paths`'s)."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..geometry import best_rigid_motion


def rotation(axis, angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` radians about ``axis``: a coordinate axis 0, 1 or 2 (its
    entries exactly cos and sin), or any 3-vector (Rodrigues' formula)."""
    if np.ndim(axis) == 0:
        if axis not in (0, 1, 2):
            raise ValueError(f"a coordinate axis is 0, 1 or 2, got {axis!r}")
        c, s = np.cos(angle), np.sin(angle)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        m = np.eye(3)
        m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
        return m
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def slerp(start: np.ndarray, end: np.ndarray, s: float) -> np.ndarray:
    """The orientation a fraction ``s`` of the way from rotation matrix ``start`` to ``end``
    along the geodesic (the shortest turn between them)."""
    turn = Rotation.from_matrix(start.T @ end).as_rotvec()
    return start @ Rotation.from_rotvec(s * turn).as_matrix()


def bump(u):
    """``64 u^3 (1 - u)^3`` on [0, 1] (peak 1 at u = 1/2), zero outside; C^2."""
    u = np.clip(u, 0.0, 1.0)
    return 64 * (u * (1 - u)) ** 3


def soft_min(values, softness: float) -> float:
    """A smooth lower bound of ``min(values)`` (log-sum-exp), within ``softness log n``."""
    v = np.asarray(values, float)
    low = v.min()
    return low - softness * np.log(np.exp(-(v - low) / softness).sum())


def soft_max(a: float, b: float, softness: float) -> float:
    """A smooth upper bound of ``max(a, b)``, within ``softness log 2``."""
    return max(a, b) + softness * np.log1p(np.exp(-abs(a - b) / softness))


def turn_angle(rest, moved, weights=None) -> float:
    """The angle in degrees of the rotation that best carries the points ``rest`` onto
    ``moved`` (both ``(n, 3)``, weighted, centroids removed: Kabsch), e.g. how far a tossed
    sheet has turned over, 180 for upside down."""
    R, _ = best_rigid_motion(rest, moved, weights)
    return float(np.degrees(Rotation.from_matrix(R).magnitude()))
