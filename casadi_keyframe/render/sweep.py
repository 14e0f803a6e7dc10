"""A sweep's figure (objective, keyframe error, iterations, seconds...) against each swept
parameter: every point and start as a dot, the best per value joined by a line."""
from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt

from .frames import save_figure


def sweep_plot(swept: dict[str, list], values: list[float], figure: str,
               path) -> Path | None:
    """One panel per swept key: the figure's ``values`` (one per point and start) against the
    key's value at each point (``swept[key]``, in the same order), the best per key value
    joined by a line; None when there is nothing to draw."""
    if not values or not swept:
        return None
    keys = list(swept)
    fig, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 3.4), squeeze=False)
    for ax, key in zip(axes[0], keys):
        column = swept[key]
        levels = list(dict.fromkeys(column))
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in levels)
        levels = sorted(levels) if numeric else levels
        where = {repr(v): i for i, v in enumerate(levels)}
        xs = [where[repr(v)] for v in column]
        ys = list(values)
        ax.scatter(xs, ys, s=14, alpha=0.6, label="points")
        low = [min(y for x, y in zip(xs, ys) if x == i) for i in range(len(levels))]
        ax.plot(range(len(levels)), low, "-o", color="C1", ms=4, label="best")
        ax.set_xticks(range(len(levels)), [f"{v:g}" if numeric else str(v) for v in levels])
        ax.set_xlabel(key)
        ax.set_ylabel(figure)
        if min(ys) > 0 and max(ys) > 100 * min(ys):
            ax.set_yscale("log")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"{figure} across the sweep ({len(values)} points)", fontsize=10)
    fig.tight_layout()
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
