"""What the command line's options read: overrides and grids (``KEY=VALUE``), numbers with
a lower bound, time steps, coarser meshes, multiple shooting's options and homotopy levels,
each refused by the option's name when it does not parse.  A ``KEY=VALUE`` item is read by
the solve request's one reader (:mod:`casadi_keyframe.optimize.settings`)."""
from __future__ import annotations

import argparse
from fractions import Fraction

import numpy as np

from ..loading import OverrideError, check_overrides
from ..optimize.settings import key_value, parse_value, split_top


def parse_overrides(items, option: str = "--set", example: str = "agents=50") -> dict:
    """``["agents=50", "cutoff=hard", "dt=1/60"]`` -> ``{"agents": 50, "cutoff": "hard",
    "dt": 0.016666666666666666}``: Python literals, fractions as floats, anything else a
    string (checked against the problem's ``build`` by :func:`loading.check_overrides`);
    ``option`` and ``example`` name the option in messages."""
    out = {}
    for item in items or []:
        key, value = key_value(item, option, example)
        out[key] = parse_value(value)
    return out


def parse_grid(items) -> dict:
    """``["weight=10,100", "dt=1/30,1/60", "x0=(0,1),(2,3)"]`` -> ``{"weight": [10, 100],
    "dt": [0.0333, 0.0167], "x0": [(0, 1), (2, 3)]}``: each value as :func:`parse_overrides`
    reads it, split at the commas outside brackets and quotes."""
    out = {}
    for item in items or []:
        key, values = key_value(item, "--grid", "weight=10,100")
        if key in out:
            raise ValueError(f"--grid {key} is given twice: list all its values in one --grid")
        out[key] = [parse_value(v) for v in split_top(values)]
    return out


def option_items(texts, option: str, example: str) -> list[dict]:
    """``["init=blend,workers=2", ...]`` (a repeatable KEY=VALUE,... ``option``) as dicts."""
    return [parse_overrides(split_top(t), option, example) for t in texts or []]


def at_least(kind, low, *, strict: bool = False):
    """An argparse type: a ``kind`` (int or float) ``>= low`` (``> low`` if ``strict``)."""
    what = (f"{'a whole number' if kind is int else 'a number'} {'>' if strict else '>='} "
            f"{low}")

    def convert(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects {what}, got {text!r}") from None
        if not (value > low if strict else value >= low) or not np.isfinite(value):
            raise argparse.ArgumentTypeError(f"expects {what}, got {text}")
        return value

    convert.__name__ = kind.__name__  # argparse names the type in some messages
    return convert


positive_int = at_least(int, 1)


def parse_time_steps(text: str | None) -> list[float] | None:
    """``"1/15,1/30,1/60"`` (fractions or decimals, seconds) -> ``[0.0667, 0.0333, 0.0167]``."""
    if not text:
        return None
    try:
        return [float(Fraction(item.strip())) for item in text.split(",")]
    except (ValueError, ZeroDivisionError):
        raise ValueError(f"--continuation expects time steps in seconds separated by commas, "
                         f"coarse to fine, e.g. 1/15,1/30,1/60; got {text!r}") from None


def parse_resolutions(module, items) -> list[dict] | None:
    """``["rows=12,cols=12", "rows=25,cols=25"]`` -> build overrides of the coarser meshes,
    each checked against the problem's ``build``; ``["none"]`` -> ``[]`` (the file's default
    meshes off); no items -> None (the file's defaults)."""
    if not items:
        return None
    if [i.strip().lower() for i in items] == ["none"]:
        return []
    out = []
    for item in items:
        pairs = split_top(item)
        if not pairs:
            raise ValueError(f"--resolution expects KEY=VALUE,... such as rows=12,cols=12, "
                             f"got {item!r}")
        out.append(check_overrides(module, parse_overrides(pairs)))
    return out


def parse_shooting(segments, items: list[dict], scheduler) -> dict | None:
    """``--segments K``, the ``--shooting`` items (each read as a dict) and ``--scheduler
    ADDRESS`` as multiple shooting's options over the problem file's (None: the file's);
    checked here, so a bad one is refused before the build."""
    from ..optimize.shooting import shooting_options

    out = {} if segments is None else {"segments": segments}
    for item in items:
        out.update(item)
    if scheduler is not None:
        out["scheduler"] = scheduler
    if not out:
        return None
    try:
        shooting_options({"segments": 2, **out})  # every option checked (the count later)
    except ValueError as err:
        raise ValueError(f"--shooting: {err}") from None
    return out


def parse_levels(module, items: list[dict]) -> list[dict] | None:
    """The ``--homotopy`` items (each read as a dict) as build overrides, each checked
    against the problem's ``build``; None without any."""

    if not items:
        return None
    for item in items:
        if not item:
            raise ValueError("--homotopy expects KEY=VALUE,... such as contact=3")
    try:
        return [check_overrides(module, item) for item in items]
    except OverrideError as err:
        raise ValueError(f"--homotopy: {err}") from None
