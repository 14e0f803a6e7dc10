"""Results on disk: ``result.npz`` (controls, trajectory, history) and ``summary.json``."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def save_result(result, out_dir, *, problem_name: str, overrides: dict | None = None) -> dict:
    """Write ``result.npz`` and ``summary.json`` into ``out_dir``; return the summary."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    traj = result.trajectory
    hist = result.history
    np.savez_compressed(
        out / "result.npz", u=result.x, jac=result.jac, x=traj.x, v=traj.v, dt=traj.dt,
        history_objective=np.array([h["objective"] for h in hist]),
        history_keyframe_error=np.array([h["keyframe_error"] for h in hist]),
        history_seconds=np.array([h["seconds"] for h in hist]))
    summary = {"problem": problem_name, "overrides": overrides or {}, **result.summary()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_jsonable))
    return summary


def load_result(out_dir) -> dict:
    """The arrays of a saved ``result.npz`` as a dict."""
    with np.load(Path(out_dir) / "result.npz") as data:
        return {k: data[k] for k in data.files}


def _jsonable(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")
