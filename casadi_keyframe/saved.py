"""A saved run read back as what it shows: the problem rebuilt from its file and overrides,
and the trajectory (stored in ``result.npz``, or simulated from a checkpoint's controls).

``casadi-keyframe render`` and ``export`` both start here, so that what a picture draws and
what an export writes come from one reading of the folder.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from .io import RESULT, read_run, run_file
from .state import Trajectory


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
    from .loading import load_problem

    path = saved_file(source)
    run = read_run(path)
    meta, arrays = run["meta"], run["arrays"]
    name = meta.get("problem_file")
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
