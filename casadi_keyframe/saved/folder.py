"""A results folder: ``result.npz`` (controls, trajectory, history), ``summary.json`` and
``checkpoint.npz``, written by :func:`save_result` and read back by :func:`read_run`
(checked: the arrays fit together) and :func:`load_saved` (the problem rebuilt from its
file and overrides, the trajectory stored or simulated).  ``solve --resume``, ``render``
and ``export`` all start here.  Both ``.npz`` files carry ``meta`` (the problem's name and
file, the overrides, the method...) as JSON, so either is enough to resume or draw a run.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..state import Trajectory
from .files import (FileDamaged, as_json, read_json, read_npz, writable_folder, write_json,
                    write_npz)

RESULT, SUMMARY, CHECKPOINT = "result.npz", "summary.json", "checkpoint.npz"


def save_result(result, out_dir, *, problem_name: str, overrides: dict | None = None,
                **meta) -> dict:
    """Write ``result.npz`` and ``summary.json`` into ``out_dir``; return the summary.

    ``meta`` (e.g. ``problem_file``, ``resumed_from``) joins the summary and the npz's
    ``meta``."""
    out = writable_folder(out_dir, "out_dir")
    summary = {"problem": problem_name, "overrides": overrides or {}, **meta,
               **result.summary()}
    traj, hist = result.trajectory, result.history
    about = {k: summary[k] for k in ("problem", "overrides", *meta, "method", "gradient",
                                     "status", "nit", "fun")}
    write_npz(out / RESULT, compressed=True, u=result.x, jac=result.jac, x=traj.x, v=traj.v,
              dt=traj.dt, meta=np.array(json.dumps(about, default=as_json)),
              history_objective=np.array([h["objective"] for h in hist]),
              history_keyframe_error=np.array([h["keyframe_error"] for h in hist]),
              history_seconds=np.array([h["seconds"] for h in hist]),
              history_stage=np.array([h.get("stage", 0) for h in hist], dtype=int),
              history_dt=np.array([h.get("dt", np.nan) for h in hist], dtype=float),
              history_particles=np.array([h.get("particles", 0) for h in hist], dtype=int),
              history_round=np.array([h.get("round", -1) for h in hist], dtype=int),
              start_objective=np.array(_or_nan(result.start["objective"])),
              start_keyframe_error=np.array(_or_nan(result.start["keyframe_error"])))
    write_json(out / SUMMARY, summary)
    return summary


def input_record(problem) -> dict:
    """What a run keeps of where its problem came from, so that it stands alone: the folder
    its overrides' relative paths resolve in (``folder``) and each file the problem was built
    from (``inputs``: absolute path -> SHA-256 of its content)."""
    return {"folder": os.getcwd(), "inputs": {str(p): file_digest(p) for p in problem.inputs}}


def file_digest(path) -> str:
    """The SHA-256 of a file's content, in hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_inputs(meta: dict, path, now=None) -> None:
    """Refuse (ValueError naming the file) a run read back from ``path`` whose input files
    changed or went missing since it ran; with ``now`` (a problem's ``inputs``), also one
    that problem does not read the same files as."""
    recorded = meta.get("inputs") or {}
    for name, digest in recorded.items():
        if not Path(name).is_file():
            raise ValueError(f"{path} was solved from {name}, which is gone: put it back, or "
                             "solve again")
        if file_digest(name) != digest:
            raise ValueError(f"{path} was solved from {name}, which has changed since: "
                             "restore it, or solve again from the new file")
    if now is not None and sorted(map(str, now)) != sorted(recorded):
        raise ValueError(f"{path} was solved from the files {sorted(recorded) or 'none'}, this "
                         f"problem reads {sorted(map(str, now)) or 'none'}: give the same files")


@contextlib.contextmanager
def working_directory(folder):
    """Run the block in ``folder`` (None: where we are), then come back."""
    here = os.getcwd()
    if folder is not None and Path(folder).is_dir():
        os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(here)


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
    written before files carried it, from the ``summary.json`` beside it.  Read by
    :func:`~casadi_keyframe.files.read_npz` (nothing unpickled); a damaged file, or one
    whose arrays do not fit together, is a :class:`~casadi_keyframe.files.FileDamaged`
    naming what is wrong and the run's other file to use instead."""
    path = run_file(source)
    fix = _instead(path)
    arrays = read_npz(path, required=("u",), fix=fix)
    u = _real(arrays.pop("u"), "u", path, fix, ndim=1)
    if "meta" in arrays:
        meta = _meta(arrays.pop("meta"), path, fix)
    elif (path.parent / SUMMARY).is_file():
        meta = _meta(read_json(path.parent / SUMMARY, fix=fix), path.parent / SUMMARY, fix)
    else:
        raise FileDamaged(path, f"does not say which problem it solves (no 'meta' and no "
                                f"{SUMMARY} beside it): not a checkpoint or result of "
                                "casadi-keyframe", fix)
    _check_trajectory(arrays, path, fix)
    return {"path": path, "u": u, "meta": meta, "arrays": arrays}


def _instead(path: Path) -> str:
    """What to do when the run file ``path`` is damaged: the run's other file, if there is
    one, or solve again."""
    other = path.parent / (RESULT if path.name == CHECKPOINT else CHECKPOINT)
    again = f"or solve again (--out {path.parent})"
    if other != path and other.is_file():
        what = "its best controls" if other.name == CHECKPOINT else "its result"
        return f"give the run's other file {other} ({what}) instead, {again}"
    return f"solve the problem again (--out {path.parent})"


def _real(array, name: str, path: Path, fix: str, *, ndim: int) -> np.ndarray:
    """``array`` as float64 if it is ``ndim``-dimensional, real and finite."""
    if array.dtype.kind not in "fiu" or array.ndim != ndim or not np.all(np.isfinite(array)):
        raise FileDamaged(path, f"has an array {name!r} that is not {ndim}-D finite real "
                                f"numbers (dtype {array.dtype}, shape {array.shape})", fix)
    return np.asarray(array, dtype=float)


def _meta(value, path: Path, fix: str) -> dict:
    """The run's ``meta`` (a JSON text in an npz, or a summary's dict), checked to name its
    problem and overrides."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind != "U" or value.ndim != 0:
            raise FileDamaged(path, f"has a 'meta' that is not text (dtype {value.dtype})", fix)
        try:
            value = json.loads(str(value))
        except json.JSONDecodeError as err:
            raise FileDamaged(path, f"has a 'meta' that is not valid JSON ({err.msg})",
                              fix) from None
    if (not isinstance(value, dict) or not isinstance(value.get("problem"), str)
            or not isinstance(value.get("overrides", {}), dict)):
        raise FileDamaged(path, "has a 'meta' that does not name its problem and overrides",
                          fix)
    return value


def _check_trajectory(arrays: dict, path: Path, fix: str) -> None:
    """A stored trajectory's ``x``, ``v`` (frames, particles, dim) and ``dt`` agree, and the
    history arrays have one entry per iteration each (converted to float in place)."""
    if any(k in arrays for k in ("x", "v", "dt")):
        missing = [k for k in ("x", "v", "dt") if k not in arrays]
        if missing:
            raise FileDamaged(path, f"is missing array {missing[0]!r} of its trajectory", fix)
        x = arrays["x"] = _real(arrays["x"], "x", path, fix, ndim=3)
        v = arrays["v"] = _real(arrays["v"], "v", path, fix, ndim=3)
        dt = _real(arrays["dt"], "dt", path, fix, ndim=0)
        if v.shape != x.shape or not dt > 0:
            raise FileDamaged(path, f"has a trajectory that does not fit together (x "
                                    f"{x.shape}, v {v.shape}, dt {dt})", fix)
    history = {k: a for k, a in arrays.items() if k.startswith(("history_", "start_"))}
    for name, a in history.items():
        if a.dtype.kind not in "fiu" or a.ndim != (1 if name.startswith("h") else 0):
            raise FileDamaged(path, f"has an array {name!r} that is not real numbers of "
                                    f"the right shape (dtype {a.dtype}, shape {a.shape})", fix)
    lengths = {k: len(a) for k, a in history.items() if k.startswith("history_")}
    if len(set(lengths.values())) > 1:
        raise FileDamaged(path, f"has history arrays of different lengths "
                                f"({', '.join(f'{k} {n}' for k, n in lengths.items())})", fix)


class SavedRun(NamedTuple):
    """A run on disk: its ``problem`` (rebuilt), ``trajectory``, the file's ``meta`` and
    other ``arrays`` (history...), and the ``path`` it was read from."""

    problem: object
    trajectory: Trajectory
    meta: dict
    arrays: dict
    path: Path


def saved_file(source) -> Path:
    """The file a saved run is read from: ``source`` if it is a file, else its folder's
    ``result.npz``, or its ``checkpoint.npz`` alone (FileNotFoundError if neither)."""
    source = Path(source)
    return source / RESULT if (source / RESULT).is_file() else run_file(source)


def load_saved(source, *, quiet: bool = False) -> SavedRun:
    """Read the run in ``source`` (a results folder, preferring its ``result.npz``, or a
    ``.npz`` file) and rebuild its problem; a ValueError if the controls do not fit it."""
    from ..loading import load_problem

    path = saved_file(source)
    run = read_run(path)
    meta, arrays = run["meta"], run["arrays"]
    check_inputs(meta, path)
    name = meta.get("problem_file")
    with working_directory(meta.get("folder")):
        prob = load_problem(name if name and Path(name).is_file() else meta["problem"],
                            **meta.get("overrides", {}))
    if run["u"].size != prob.size:
        raise ValueError(f"{path} holds {run['u'].size} controls but {prob.name} built with "
                         f"{meta.get('overrides', {})} has {prob.size}")
    check_trajectory(run, prob)
    if "x" in arrays:
        traj = Trajectory(arrays["x"], arrays["v"], float(arrays["dt"]))
    else:
        if not quiet:
            print(f"{prob.name}: {path.name} holds controls only: simulating them")
        traj = prob.simulate(run["u"])
    return SavedRun(prob, traj, meta, arrays, path)


def check_trajectory(run: dict, prob) -> None:
    """A ValueError if the trajectory a run file stores (:func:`.io.read_run`) is not one of
    ``prob``: another number of frames, particles or dimensions, or another dt."""
    arrays = run["arrays"]
    if "x" not in arrays:
        return
    frames = (prob.steps + 1, prob.model.n, prob.model.dim)
    if arrays["x"].shape != frames or not np.isclose(float(arrays["dt"]), prob.dt):
        raise ValueError(f"{run['path']} holds a trajectory of shape {arrays['x'].shape} at dt "
                         f"{float(arrays['dt']):.6g} s, but {prob.name} built with "
                         f"{run['meta'].get('overrides', {})} has {frames} at dt "
                         f"{prob.dt:.6g} s: the file was altered, or the problem file changed "
                         "since the run")
