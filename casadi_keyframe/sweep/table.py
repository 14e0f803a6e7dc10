"""A sweep's table of points (CSV always, Parquet when pyarrow is installed) and the best
point of each group (the plot of a figure against the swept parameters is
:mod:`..render.sweep`).

The table is made from the points' ``row.json`` files, so a resumed sweep's table holds
the points solved by earlier runs too.  Parquet is optional because pyarrow is large to
install for a sweep that needs none of it; ``pandas.read_csv`` reads the CSV as well.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

from ..saved import atomic_path
from .tasks import ERROR

CSV, PARQUET = "sweep.csv", "sweep.parquet"
_HEAD = ("point", "start", "status", "objective", "keyframe_error", "iterations", "seconds",
         "reason", "path")


def columns(rows: list[dict], keys) -> list[str]:
    """The table's columns: the point's name, the swept keys, the main figures that some row
    has, then every other field in the order first seen (the keyframe misses, memory...)."""
    head = ["point", *keys, *(c for c in _HEAD[1:] if any(c in row for row in rows))]
    rest = [c for row in rows for c in row if c not in head and c != "label"]
    return head + list(dict.fromkeys(rest))


def write_tables(rows: list[dict], folder, keys) -> list[Path]:
    """``sweep.csv`` (and ``sweep.parquet`` if pyarrow imports) in ``folder``, each written
    atomically; the paths written."""
    folder = Path(folder)
    names = columns(rows, keys)
    with atomic_path(folder / CSV) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=names, extrasaction="ignore")
        writer.writeheader()
        writer.writerows({k: _cell(row.get(k)) for k in names} for row in rows)
    written = [folder / CSV]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    table = pa.table({k: [_parquet_cell(row.get(k)) for row in rows] for k in names})
    with atomic_path(folder / PARQUET) as tmp:
        pq.write_table(table, tmp)
    return written + [folder / PARQUET]


def _cell(value):
    return "" if value is None else value


def _parquet_cell(value):
    """Mixed columns (a string in a number column) become text, so every column has a type."""
    return value if value is None or isinstance(value, (int, float, str, bool)) else str(value)


def value_of(row: dict, figure: str) -> float | None:
    """The row's ``figure`` as a finite float, or None (a failed point, a missing figure)."""
    if row.get("status") == ERROR:
        return None
    try:
        value = float(row.get(figure))
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def best_per_group(rows: list[dict], figure: str, group_by) -> list[dict]:
    """For each combination of the ``group_by`` keys' values (all rows in one group when it
    is empty), the point with the lowest ``figure``: ``{"group", "point", figure, "path"}``."""
    best: dict = {}
    for row in rows:
        value = value_of(row, figure)
        if value is None:
            continue
        group = tuple((k, row.get(k)) for k in group_by)
        if group not in best or value < best[group][1]:
            best[group] = (row, value)
    return [{"group": dict(group), "point": row["point"], figure: value, "path": row["path"]}
            for group, (row, value) in best.items()]
