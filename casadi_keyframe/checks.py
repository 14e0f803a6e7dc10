"""Argument checks whose errors say what was wrong: finite and positive numbers and fields,
and times on a step grid."""
from __future__ import annotations

import numpy as np


def check_number(what: str, value, *, positive: bool = False):
    """``value`` (a number, or an array of numbers) as float, or a ValueError naming ``what``
    if any is not finite (or, with ``positive``, not positive)."""
    arr = np.asarray(value, float)
    if not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0)):
        kind = "positive and finite" if positive else "finite"
        raise ValueError(f"{what} must be {kind}, got {value}")
    return float(arr) if arr.ndim == 0 else arr


def check_fields(obj, *, finite=(), positive=()) -> None:
    """:func:`check_number` on the named attributes of ``obj`` (the ``finite`` ones, then the
    ``positive`` ones); the error names the first bad one as ``Type.name``."""
    for names, must_be_positive in ((finite, False), (positive, True)):
        for name in names:
            check_number(f"{type(obj).__name__}.{name}", getattr(obj, name),
                         positive=must_be_positive)


def frame_at(t: float, dt: float, what: str) -> int:
    """The frame k with ``t = k dt`` (to round-off), or a ValueError naming ``what`` if t is
    not finite or falls between two frames of the grid."""
    if not np.isfinite(t):
        raise ValueError(f"{what} must be a finite time in s, got {t}")
    k = int(round(t / dt))
    if abs(t - k * dt) > 1e-9 * max(1.0, abs(t)):
        raise ValueError(f"{what} = {t:.6g} s is not a whole number of steps of dt = {dt:.6g} s "
                         f"({t / dt:.6g} steps); choose it on the time grid")
    return k
