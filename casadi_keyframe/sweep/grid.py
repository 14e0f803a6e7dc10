"""The points of a sweep: the Cartesian product of a grid of overrides, times K starts.

A point is named by what it solves (its grid values and its start), never by its place in
the list, so the same point has the same folder whichever grid it is part of and however
the grid is ordered: ``--resume`` finds it again, and a grid grown by one value re-solves
only the new points.  Start 0 is the problem's own start (``--starts 1`` is a plain solve
of each point); start k > 0 adds a random perturbation drawn from a generator seeded by
``(seed, k)``, so a start is the same on every machine and in every run.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import re
from dataclasses import dataclass, field

import numpy as np

from ..controls import StepForces

_UNSAFE = re.compile(r"[^A-Za-z0-9_.,=+-]+")
_MAX_NAME = 80


@dataclass(frozen=True)
class Point:
    """One solve of a sweep: the swept ``values`` (the grid's keys, in the grid's order),
    the ``start`` (0 for the problem's own) and the folder ``name`` it writes to."""

    values: dict
    start: int = 0
    name: str = field(default="", compare=False)

    @property
    def label(self) -> str:
        """``"weight=10 alpha=0.001 start=1"``: how the point is printed."""
        parts = [f"{k}={_text(v)}" for k, v in self.values.items()]
        return " ".join(parts + ([f"start={self.start}"] if self.start else [])) or "(base)"


def points(grid: dict, starts: int = 1) -> list[Point]:
    """Every combination of ``grid``'s values (``{"key": [v1, v2, ...]}``, keys in order)
    with every start ``0 .. starts - 1``; ValueError for an empty value list or a repeated
    value (two points would share a folder)."""
    if starts < 1:
        raise ValueError(f"--starts must be at least 1 (the problem's own start), got {starts}")
    for key, values in grid.items():
        if len(values) == 0:
            raise ValueError(f"--grid {key}= gives no values: list them, e.g. {key}=1,2,3")
        texts = [_text(v) for v in values]
        if len(set(texts)) < len(texts):
            raise ValueError(f"--grid {key} repeats a value ({', '.join(texts)}): give each "
                             "value once")
    combos = itertools.product(*grid.values()) if grid else [()]
    out = []
    for combo in combos:
        values = dict(zip(grid, combo))
        out += [Point(values, k, folder_name(values, k)) for k in range(starts)]
    return out


def folder_name(values: dict, start: int = 0) -> str:
    """A folder name made of the values, e.g. ``weight=10,alpha=0.001,start=1``; a name
    that would be too long or that could clash after cleaning ends in a hash of the values."""
    parts = [f"{k}={_text(v)}" for k, v in values.items()]
    parts += [f"start={start}"] if start else []
    text = ",".join(parts) or "base"
    safe = _UNSAFE.sub("_", text)
    if safe != text or len(safe) > _MAX_NAME:
        digest = hashlib.sha1(json.dumps([values, start], sort_keys=True,
                                         default=str).encode()).hexdigest()[:10]
        safe = f"{safe[:_MAX_NAME - 11]}-{digest}"
    return safe


def _text(value) -> str:
    """A value as typed on the command line: ``0.001``, ``hard``, ``(1.0, 2.0)``."""
    return value if isinstance(value, str) else repr(value)


def start_controls(problem, start: int, *, seed: int = 0, scale: float = 0.5):
    """The controls start ``start`` begins from: None (the problem's own) for start 0, else
    the problem's own plus a perturbation from a generator seeded by ``(seed, start)``:
    per-step forces of ``scale`` m/s^2 rms times each particle's mass, or initial
    velocities of ``scale`` m/s rms; clipped to the control bounds."""
    if start == 0:
        return None
    controls = problem.controls
    noise = np.random.default_rng([seed, start]).standard_normal(controls.block_shape)
    if isinstance(controls, StepForces):
        noise *= problem.model.masses[controls.idx][:, None]
    lower, upper = problem.bounds()
    return np.clip(problem.initial_controls() + scale * noise.ravel(), lower, upper)
