"""A saved run read back as what it shows: the problem rebuilt from its file and overrides,
and the trajectory (stored in ``result.npz``, or simulated from a checkpoint's controls).

``casadi-keyframe render`` and ``export`` both start here, so that what a picture draws and
what an export writes come from one reading of the folder.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

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


def load_saved(source, *, quiet: bool = False) -> SavedRun:
    """Read the run in ``source`` (a results folder, preferring its ``result.npz``, or a
    ``.npz`` file) and rebuild its problem; a ValueError if the controls do not fit it."""
    from .loading import load_problem

    source = Path(source)
    path = source / RESULT if (source / RESULT).is_file() else run_file(source)
    run = read_run(path)
    meta, arrays = run["meta"], run["arrays"]
    name = meta.get("problem_file")
    prob = load_problem(name if name and Path(name).is_file() else meta["problem"],
                        **meta.get("overrides", {}))
    if run["u"].size != prob.size:
        raise ValueError(f"{path} holds {run['u'].size} controls but {prob.name} built with "
                         f"{meta.get('overrides', {})} has {prob.size}")
    if "x" in arrays:
        traj = Trajectory(arrays["x"], arrays["v"], float(arrays["dt"]))
    else:
        if not quiet:
            print(f"{prob.name}: {path.name} holds controls only: simulating them")
        traj = prob.simulate(run["u"])
    return SavedRun(prob, traj, meta, arrays, path)
