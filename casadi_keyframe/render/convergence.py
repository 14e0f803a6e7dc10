"""The optimizer's history: objective and keyframe error versus iteration and wall time."""
from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from .flock import AGENT, PARTICLE
from .frames import save_figure


def _series(history, key):
    vals = np.array([np.nan if h.get(key) is None else float(h[key]) for h in history])
    return np.where(vals > 0, vals, np.nan)  # log scale: hide non-positive values


def convergence(result, path) -> Path:
    """Write a PNG of objective and keyframe error versus iteration and versus seconds."""
    path = Path(path)
    history = list(getattr(result, "history", None) or [])
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    try:
        fig.suptitle(f"{getattr(result, 'method', '?')} / gradient: "
                     f"{getattr(result, 'gradient', '?')}", fontsize=11)
        if not history:
            for ax in axes:
                ax.text(0.5, 0.5, "no iterations recorded", ha="center", va="center",
                        transform=ax.transAxes, color="gray")
                ax.set_xticks([]), ax.set_yticks([])
        else:
            start = getattr(result, "start", None) or {}
            if start.get("objective") is not None and np.isfinite(start["objective"]):
                history = [{"iteration": 0, "seconds": 0.0, **start}] + history
            for ax, xkey, xlabel in ((axes[0], "iteration", "iteration (0: the start)"),
                                     (axes[1], "seconds", "wall time [s]")):
                x = [h.get(xkey, i + 1) for i, h in enumerate(history)]
                style = ".-" if len(history) < 30 else "-"
                ax.plot(x, _series(history, "objective"), style, color=AGENT, label="objective")
                ax.plot(x, _series(history, "keyframe_error"), style, color=PARTICLE,
                        label="keyframe error")
                ax.set_yscale("log")
                ax.set_xlabel(xlabel)
                ax.grid(alpha=0.3, which="both", lw=0.5)
            axes[0].legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path
