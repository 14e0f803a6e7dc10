"""Results on disk: ``result.npz`` (controls, trajectory, history), ``summary.json`` and the
``checkpoint.npz`` a search keeps its best controls in.

Every file is written whole or not at all: to a temporary name in the same folder, then
moved onto its name with :func:`os.replace` (:func:`atomic_path`), so an interrupted or
killed run never leaves a half-written file, only the previous version or none.  Both
``.npz`` files carry ``meta`` (the problem's name and file, the overrides, the method...) as
JSON, so either is enough to resume a run or to draw it again.
"""
from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

import numpy as np

from .interrupts import deferred

RESULT, SUMMARY, CHECKPOINT = "result.npz", "summary.json", "checkpoint.npz"


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (same suffix, so writers pick the format) to
    write to; it replaces ``path`` when the block ends normally and is deleted otherwise
    (an exception, Ctrl-C)."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        with deferred():
            os.replace(tmp, path)
    finally:
        with deferred():
            tmp.unlink(missing_ok=True)


def write_npz(path, *, compressed: bool = False, **arrays) -> Path:
    """``np.savez`` (or ``savez_compressed``) through :func:`atomic_path`."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        (np.savez_compressed if compressed else np.savez)(f, **arrays)
    return Path(path)


def write_json(path, obj) -> Path:
    """Indented JSON (numpy scalars and arrays allowed) through :func:`atomic_path`."""
    text = json.dumps(obj, indent=2, default=_jsonable)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


class Checkpoint:
    """Where a search keeps its best controls: ``write(u, fun=, nit=, stage=, stage_dt=)``
    replaces the file with ``u`` (on the final grid), those fields and ``meta`` (what
    rebuilds the problem: ``problem``, ``problem_file``, ``overrides``; the method...)."""

    def __init__(self, path, **meta):
        self.path, self.meta = Path(path), meta

    def write(self, u, **fields) -> None:
        meta = json.dumps({**self.meta, **fields}, default=_jsonable)
        write_npz(self.path, u=np.asarray(u, dtype=float), meta=np.array(meta), **fields)


def as_checkpoint(checkpoint) -> Checkpoint | None:
    """None, a :class:`Checkpoint`, or a path made into one."""
    if checkpoint is None or isinstance(checkpoint, Checkpoint):
        return checkpoint
    return Checkpoint(checkpoint)


def save_result(result, out_dir, *, problem_name: str, overrides: dict | None = None,
                **meta) -> dict:
    """Write ``result.npz`` and ``summary.json`` into ``out_dir``; return the summary.

    ``meta`` (e.g. ``problem_file``, ``resumed_from``) joins the summary and the npz's
    ``meta``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"problem": problem_name, "overrides": overrides or {}, **meta,
               **result.summary()}
    traj, hist = result.trajectory, result.history
    about = {k: summary[k] for k in ("problem", "overrides", *meta, "method", "gradient",
                                     "status", "nit", "fun")}
    write_npz(out / RESULT, compressed=True, u=result.x, jac=result.jac, x=traj.x, v=traj.v,
              dt=traj.dt, meta=np.array(json.dumps(about, default=_jsonable)),
              history_objective=np.array([h["objective"] for h in hist]),
              history_keyframe_error=np.array([h["keyframe_error"] for h in hist]),
              history_seconds=np.array([h["seconds"] for h in hist]),
              history_stage=np.array([h.get("stage", 0) for h in hist], dtype=int),
              start_objective=np.array(_or_nan(result.start["objective"])),
              start_keyframe_error=np.array(_or_nan(result.start["keyframe_error"])))
    write_json(out / SUMMARY, summary)
    return summary


def _or_nan(value) -> float:
    return np.nan if value is None else float(value)


def run_file(source) -> Path:
    """The file a run is resumed or drawn from: ``source`` if it is a file, else the newer of
    ``checkpoint.npz`` and ``result.npz`` in the folder ``source``."""
    path = Path(source)
    if path.is_file():
        return path
    if not path.is_dir():
        raise FileNotFoundError(f"{path} is neither a results folder nor a .npz file")
    found = [p for p in (path / CHECKPOINT, path / RESULT) if p.is_file()]
    if not found:
        raise FileNotFoundError(f"{path} holds neither {CHECKPOINT} nor {RESULT}: nothing to "
                                "resume or draw")
    return max(found, key=lambda p: p.stat().st_mtime_ns)


def read_run(source) -> dict:
    """``{"path", "u", "meta", "arrays"}`` of a checkpoint or a result (``source``: the file
    or its folder, see :func:`run_file`).  ``meta`` comes from the file, or for a result
    written before files carried it, from the ``summary.json`` beside it."""
    path = run_file(source)
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError) as err:
        raise ValueError(f"cannot read {path}: {err}") from None
    if "u" not in arrays:
        raise ValueError(f"{path} holds no controls 'u': not a checkpoint or result of "
                         "casadi-keyframe")
    if "meta" in arrays:
        meta = json.loads(str(arrays.pop("meta")))
    elif (path.parent / SUMMARY).is_file():
        meta = json.loads((path.parent / SUMMARY).read_text())
    else:
        raise ValueError(f"{path} does not say which problem it solves (no 'meta' and no "
                         f"{SUMMARY} beside it)")
    return {"path": path, "u": arrays.pop("u"), "meta": meta, "arrays": arrays}


def _jsonable(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")
