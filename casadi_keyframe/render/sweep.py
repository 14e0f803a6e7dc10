"""A sweep's figure (objective, keyframe error, iterations, seconds...) against each swept
parameter: every point and start as a dot, the best per value joined by a line."""
from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from ..sweep.table import value_of
from .frames import save_figure


def sweep_plot(rows: list[dict], keys, figure: str, path) -> Path | None:
    """One panel per swept key: ``figure`` of every point (every start) against the key's
    values, the best per value joined by a line; None if no point has the figure."""
    rows = [r for r in rows if value_of(r, figure) is not None]
    if not rows or not keys:
        return None
    fig, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 3.4), squeeze=False)
    for ax, key in zip(axes[0], keys):
        values = list(dict.fromkeys(r.get(key) for r in rows))
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
        values = sorted(values) if numeric else values
        where = {repr(v): i for i, v in enumerate(values)}
        xs = [where[repr(r.get(key))] for r in rows]
        ys = [value_of(r, figure) for r in rows]
        ax.scatter(xs, ys, s=14, alpha=0.6, label="points")
        low = [min(y for x, y in zip(xs, ys) if x == i) for i in range(len(values))]
        ax.plot(range(len(values)), low, "-o", color="C1", ms=4, label="best")
        ax.set_xticks(range(len(values)), [f"{v:g}" if numeric else str(v) for v in values])
        ax.set_xlabel(key)
        ax.set_ylabel(figure)
        if min(ys) > 0 and max(ys) > 100 * min(ys):
            ax.set_yscale("log")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"{figure} across the sweep ({len(rows)} points)", fontsize=10)
    fig.tight_layout()
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
