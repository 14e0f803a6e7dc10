"""When a keyframe counts as met, and a motion as physical: tolerance pairs, the limits of
stretch and depth, and the phrases that name a miss beyond one (the goal of a search, see
:mod:`casadi_keyframe.optimize.goal`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_POSITION_TOLERANCE = 0.01  # of a target's extent; in length units when it has none
VELOCITY_TIME = 0.1  # s: a velocity tolerance is the position tolerance per this time


def tolerance_pair(tolerance, label) -> tuple:
    """``tolerance`` (None, one number: the position's, or a pair ``(position, velocity)``
    whose entries may be None) as a checked pair; ``inf`` turns a check off."""
    pair = (tolerance, None) if tolerance is None or np.isscalar(tolerance) else tuple(tolerance)
    if len(pair) != 2:
        raise ValueError(f"{label}: tolerance is a number (the rms position miss) or a pair "
                         f"(position, velocity), got {tolerance!r}")
    for value in pair:
        if value is not None and not (isinstance(value, (int, float, np.floating, np.integer))
                                      and not isinstance(value, bool) and value > 0):
            raise ValueError(f"{label}: a tolerance must be a number > 0 (inf: not checked) "
                             f"or None (the default), got {tolerance!r}")
    return tuple(None if v is None else float(v) for v in pair)


def shortfall_phrase(label, miss, checks) -> str | None:
    """``"label: rms position miss 0.55 (tolerance 0.006), ..."`` for the ``(key, what,
    tolerance)`` checks of ``miss`` that fail, or None."""
    over = [f"{what} {miss[key]:.3g} (tolerance {tol:.3g})" for key, what, tol in checks
            if key in miss and tol is not None and np.isfinite(tol) and not miss[key] <= tol]
    return f"{label}: {', '.join(over)}" if over else None


def keyframe_tolerance(tolerance: tuple, x, v) -> tuple:
    """A state keyframe's ``(position, velocity)`` tolerance over its bound targets ``x``,
    ``v`` (None where it has no target), defaults filled in: positions 1 % of the target's
    extent (its bounding box's longest side; 0.01 length units for a single point),
    velocities the position tolerance per 0.1 s."""
    position, velocity = tolerance
    if x is not None and position is None:
        extent = float(np.ptp(x, axis=0).max()) if len(x) > 1 else 0.0
        position = DEFAULT_POSITION_TOLERANCE * (extent if extent > 0 else 1.0)
    if v is not None and velocity is None:
        scale = position if position is not None and np.isfinite(position) else (
            DEFAULT_POSITION_TOLERANCE)
        velocity = scale / VELOCITY_TIME
    return (position if x is not None else None, velocity if v is not None else None)


def center_tolerance(tolerance: tuple, has_x: bool, has_v: bool) -> tuple:
    """A centre-of-mass keyframe's ``(position, velocity)`` tolerance, defaults filled in:
    0.01 length units, and that per 0.1 s (None where it has no target)."""
    position, velocity = tolerance
    position = DEFAULT_POSITION_TOLERANCE if position is None else position
    if velocity is None:
        velocity = (position if np.isfinite(position) else
                    DEFAULT_POSITION_TOLERANCE) / VELOCITY_TIME
    return (position if has_x else None, velocity if has_v else None)


@dataclass(frozen=True)
class PhysicalLimits:
    """When a cloth's motion counts as physical, at every frame: no spring longer than
    ``stretch`` times its rest length (torn), no particle deeper than ``depth`` metres inside
    a body (sunk).  A result is converged only within them as well as its tolerances."""

    stretch: float = 1.3
    depth: float = 0.005

    def __post_init__(self):
        if not (np.isfinite(self.stretch) and self.stretch > 1):
            raise ValueError(f"PhysicalLimits.stretch must be a finite number > 1 (a spring's "
                             f"length over its rest length), got {self.stretch!r}")
        if not (self.depth > 0):
            raise ValueError(f"PhysicalLimits.depth must be > 0 metres (inf: not checked), "
                             f"got {self.depth!r}")

    def shortfall(self, report: dict) -> list[str]:
        """What a model's ``physical_report`` breaks of these limits, one phrase each."""
        out = []
        if report["max_stretch"] > self.stretch:
            out.append(f"torn: stretch {report['max_stretch']:.3g} at frame "
                       f"{report['max_stretch_frame']} (limit {self.stretch:.3g})")
        depth = report.get("max_penetration", 0.0)
        if depth > self.depth:
            out.append(f"sunk: {1e3 * depth:.3g} mm inside a body at frame "
                       f"{report['max_penetration_frame']} (tolerance {1e3 * self.depth:.3g} mm)")
        return out
