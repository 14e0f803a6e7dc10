"""How multiple shooting runs: :class:`ShootingOptions` and :func:`shooting_options`, which
checks what ``solve(..., shooting=...)`` and the command line's ``--segments/--shooting``
give."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..options import TypedOptions
from .nodes import INITS

FORMULATIONS = ("lagrangian", "ipopt")
PLACES = ("equal", "growth")


@dataclass(frozen=True)
class ShootingOptions(TypedOptions):
    """How multiple shooting runs (``solve(..., shooting=...)``), field by field."""

    segments: int
    """K, the segments the horizon is cut into (1: single shooting)."""
    init: str = "passive"
    """Where the node states start (:mod:`.nodes`): ``"passive"``, ``"guess"`` (the start
    controls' run: no defect), ``"target"``, ``"blend"``, or a function of the problem
    giving a path of positions."""
    rounds: int = 8
    """Augmented-Lagrangian rounds at most (the stage's ``maxiter`` shared among them)."""
    workers: int = 1
    """Processes sweeping the segments (1: this one)."""
    scheduler: str | None = None
    """A Dask scheduler's address, to sweep the segments on its workers instead."""
    penalty: float = 1.0
    """Factor on the defects' starting weights (1: a defect as large as the tolerance costs
    what the keyframe's miss of that size costs)."""
    growth: float = 10.0
    """Factor a weight grows by where its defect did not shrink to a quarter."""
    polish: bool = True
    """End with the stage's single-shooting search from the result."""
    hold: bool = True
    """Hold the StateKeyframes by multipliers too (``"lagrangian"`` only)."""
    formulation: str = "lagrangian"
    """``"lagrangian"`` (the defects held by multipliers, rounds of the solve's method) or
    ``"ipopt"`` (IPOPT with the defects as constraints, :mod:`.ipopt_form`)."""
    place: str = "equal"
    """Where the segments meet: ``"equal"`` (equal lengths) or ``"growth"`` (an equal share
    of the backward growth measured on the start's run each, :mod:`.placement`)."""


def shooting_options(value) -> ShootingOptions | None:
    """``value`` (None, a whole number K, a dict of :class:`ShootingOptions` fields, or one)
    as checked options, or None for no multiple shooting; ValueError naming what is wrong."""
    opts = ShootingOptions.read(value, "shooting", single=(int, np.integer),
                                takes="a number of segments, a dict of options or "
                                      "ShootingOptions")
    if opts is None:
        return None
    if opts.formulation not in FORMULATIONS:
        raise ValueError(f"shooting formulation must be one of {', '.join(FORMULATIONS)}, got "
                         f"{opts.formulation!r}")
    if opts.place not in PLACES:
        raise ValueError(f"shooting place must be one of {', '.join(PLACES)}, got "
                         f"{opts.place!r}")
    if not callable(opts.init) and opts.init not in INITS:
        raise ValueError(f"shooting init must be one of {', '.join(INITS)} or a function of "
                         f"the problem giving a path of positions, got {opts.init!r}")
    for name in ("segments", "rounds", "workers"):
        got = getattr(opts, name)
        if isinstance(got, bool) or not isinstance(got, (int, np.integer)) or got < 1:
            raise ValueError(f"shooting {name} must be a whole number >= 1, got {got!r}")
    if not (np.isfinite(opts.penalty) and opts.penalty > 0 and np.isfinite(opts.growth)
            and opts.growth >= 1):
        raise ValueError(f"shooting penalty must be > 0 and growth >= 1, got "
                         f"{opts.penalty!r} and {opts.growth!r}")
    return opts
