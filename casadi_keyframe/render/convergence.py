"""The optimizer's history: objective, keyframe error and control cost versus iteration and
wall time.

Drawn so that each line stays readable when they meet: the objective thick and solid, the
keyframe error dashed over it (the two coincide when the control cost is small), the
control cost dotted.  Where a stage begins (a finer mesh, a finer time step, a new
augmented-Lagrangian round) a vertical line says what changed, since the objective jumps
there: it is measured on the new stage's problem.  An iterate far above the start (IPOPT's
iterates need not decrease) is drawn at the top edge as a triangle, not allowed to squash
the rest, and a keyframe error of exactly zero (every region filled) at the bottom edge.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from .flock import AGENT, PARTICLE
from .frames import save_figure

CONTROL = "#3a923a"
TOP = 10.0  # iterates above TOP x the start objective are drawn at the top edge


def convergence(result, path) -> Path:
    """Write a PNG of the history of ``result`` (anything with ``history``, ``start``,
    ``method`` and ``gradient``, as :class:`~casadi_keyframe.optimize.Result`), from its
    start at iteration 0; a search that took no iteration shows its start point alone, and
    says so."""
    path = Path(path)
    history = with_start(result)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    try:
        fig.suptitle(f"{getattr(result, 'method', '?')} / gradient: "
                     f"{getattr(result, 'gradient', '?')}", fontsize=11)
        if not history:
            for ax in axes:
                ax.text(0.5, 0.5, "no iterations recorded", ha="center", va="center",
                        transform=ax.transAxes, color="gray")
                ax.set_xticks([]), ax.set_yticks([])
            fig.tight_layout()
        else:
            notes = _draw(axes, history)
            if len(history) == 1 and history[0]["iteration"] == 0:
                notes.insert(0, "no iterations: the search ended at its start, the point "
                                "drawn at iteration 0")
            handles, labels = axes[0].get_legend_handles_labels()
            below = 0.03 * (len(notes) + 1) if notes else 0.0  # the notes under the legend
            fig.legend(handles, labels, loc="lower center", ncol=len(handles), fontsize=8,
                       frameon=False, bbox_to_anchor=(0.5, below))
            fig.tight_layout(rect=(0, 0.08 + below, 1, 1))
            for i, note in enumerate(notes):
                fig.text(0.5, below - 0.03 * (i + 1) + 0.005, note, ha="center", fontsize=8,
                         color="0.3")
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path


def with_start(result) -> list:
    """The history of ``result`` behind its start (iteration 0) where the start's objective
    is known: a search that took no iteration is its start alone."""
    history = list(getattr(result, "history", None) or [])
    start = getattr(result, "start", None) or {}
    if start.get("objective") is None or not np.isfinite(start["objective"]):
        return history
    first = history[0] if history else {}
    return [{"iteration": 0, "seconds": 0.0, **start,
             **{k: first[k] for k in ("stage", "dt", "particles", "round") if k in first}}
            ] + history


def series(history, key) -> np.ndarray:
    """The ``key`` of every record as floats (NaN where missing)."""
    return np.array([np.nan if h.get(key) is None else float(h[key]) for h in history])


def _draw(axes, history) -> list[str]:
    """Both panels' lines, limits and stage marks; the notes to print under them."""
    f, k = series(history, "objective"), series(history, "keyframe_error")
    c = f - k
    finite = f[np.isfinite(f)]
    top = TOP * (finite[0] if finite.size else 1.0)
    high = np.isfinite(f) & (f > top)
    zero = np.isfinite(k) & (k <= 0)
    positive = np.concatenate([v[np.isfinite(v) & (v > 0) & ~high] for v in (f, k, c)])
    low = positive.min() / 3 if positive.size else 1e-12
    hi_lim = min(top, positive.max() * 3) if positive.size else 1.0
    for ax, xkey, xlabel in ((axes[0], "iteration", "iteration (0: the start)"),
                             (axes[1], "seconds", "wall time [s]")):
        x = np.array([h.get(xkey, i) for i, h in enumerate(history)], float)
        alone = {"marker": "o", "ms": 5} if len(history) == 1 else {}  # a point, not a line
        ax.plot(x, _shown(f, high), color=AGENT, lw=2.2, label="objective",
                **({"marker": "o", "ms": 9} if alone else
                   {"marker": "." if len(history) < 30 else None}))
        ax.plot(x, _shown(k, high | zero), "--", color=PARTICLE, lw=1.3,
                label="keyframe error", **alone)
        ax.plot(x, _shown(c, high), ":", color=CONTROL, lw=1.3, label="control cost", **alone)
        if alone:
            ax.set_xticks([0.0])
        ax.set_yscale("log")
        ax.set_ylim(low, hi_lim)
        if high.any():
            ax.plot(x[high], np.full(high.sum(), hi_lim), "^", color=AGENT, ms=6, clip_on=False,
                    label=f"iterate above {TOP:g}x the start (off the scale)")
        if zero.any():
            ax.plot(x[zero], np.full(zero.sum(), low), "v", color=PARTICLE, ms=5,
                    clip_on=False, label="keyframe error 0 (every keyframe met)")
        staged = _stage_marks(ax, x, history)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3, which="both", lw=0.5)
    notes = ["a grey vertical line marks where a stage begins: the objective jumps there, "
             "measured on the new stage's problem"] if staged else []
    if high.any():
        count = int(high.sum())
        notes.append(f"{count} iterate{'s' * (count > 1)} rose above {TOP:g}x the "
                     f"start (up to {f[high].max():.3g}): the method's steps need not "
                     "descend (IPOPT's do not); the result is the best point")
    return notes


def _shown(values, hidden) -> np.ndarray:
    """``values`` with ``hidden`` and non-positive entries (a log scale) left out."""
    return np.where(~hidden & (values > 0), values, np.nan)


def _stage_marks(ax, x, history) -> bool:
    """A vertical line where each stage after the first begins, labelled with what
    changed: the particles (a finer mesh), the time step, or the round; whether any."""
    marked = False
    for i in range(1, len(history)):
        before, now = history[i - 1], history[i]
        if now.get("stage", 0) == before.get("stage", 0) and \
                now.get("round") == before.get("round"):
            continue
        what = []
        if now.get("particles") != before.get("particles") and now.get("particles"):
            what.append(f"{now['particles']} particles")
        if now.get("dt") != before.get("dt") and now.get("dt"):
            what.append(f"dt {now['dt']:.3g} s")
        if now.get("round") is not None and now.get("round") != before.get("round"):
            what.append(f"round {now['round']}")
        label = f"stage {now.get('stage', '?')}" + (f": {', '.join(what)}" if what else "")
        edge = (x[i - 1] + x[i]) / 2
        ax.axvline(edge, color="0.35", lw=0.9, ls=(0, (4, 3)))
        ax.text(edge, 0.97, " " + label, transform=ax.get_xaxis_transform(), rotation=90,
                va="top", ha="right", fontsize=7, color="0.25")
        marked = True
    return marked
