"""What a worker does with one point of a sweep: solve it (or run a study's point) and leave
its folder complete.

A task gets a plain dict: the problem's file and overrides, never a built problem, so the
problem is rebuilt on the worker (kernels come from the persistent kernel cache, or are
compiled once per worker).  A solve runs through :func:`.run.run_solve`, exactly as
``casadi-keyframe solve`` does, with its output in the point's folder, its printout in the
folder's ``log.txt``.  The point's ``row.json`` (its line of the sweep's table) is written
last and atomically: it is what marks the point complete for ``--resume``.  An error
inside a point becomes a row with status ``error`` and the reason, not an exception, so a
deterministic failure is not retried on every worker.
"""
from __future__ import annotations

import contextlib
import importlib
import io
import os
import resource
import socket
import sys
import threading
import time
import traceback
from pathlib import Path

from ..saved import FileDamaged, read_json
from ..saved import SUMMARY, write_json
from ..loading import ProblemFileError
from ..optimize.outcome import FAILED, STATUS

ROW, LOG = "row.json", "log.txt"
ERROR = "error"  # the status of a point that ended without a result


def failed(row: dict) -> bool:
    """Whether a point failed: no result (status ``error``) or its search failed."""
    return row.get("status") in (ERROR, STATUS[FAILED])


def run_task(spec: dict) -> dict:
    """Run one point (``spec["kind"]`` is ``"solve"`` or ``"study"``), write its
    ``row.json`` and return the row."""
    folder = Path(spec["folder"])
    folder.mkdir(parents=True, exist_ok=True)
    start, cpu = time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    with _log_to(folder / LOG) as log:
        print(f"point {spec['name']} on worker {worker}", flush=True)
        try:
            row = _KINDS[spec["kind"]](spec, folder)
        except Exception as err:  # noqa: BLE001 - a point's failure is a row, not a crash
            traceback.print_exc(file=log)
            named = isinstance(err, ProblemFileError)  # its message names the exception
            row = {"status": ERROR, "reason": _one_line(err) if named else
                   f"{type(err).__name__}: {_one_line(err)}"}
    row = {"point": spec["name"], **spec["values"], "start": spec.get("start", 0), **row,
           "seconds": time.perf_counter() - start,
           "cpu_seconds": time.process_time() - cpu, "worker": worker,
           "peak_rss_mb": peak_rss_mb(), "path": str(folder), "spec_id": spec["id"]}
    write_json(folder / ROW, row)
    return row


def read_row(folder) -> dict | None:
    """The ``row.json`` of a point folder, or None if there is none; a damaged one (cut
    short, not JSON, not a row) is a :class:`~casadi_keyframe.saved.FileDamaged`."""
    path = Path(folder) / ROW
    if not path.is_file():
        return None
    fix = "the point is solved again"
    row = read_json(path, fix=fix)
    if not isinstance(row, dict) or not isinstance(row.get("point"), str):
        raise FileDamaged(path, "is not a sweep point's row (no 'point' name)", fix)
    return row


def _solve(spec: dict, folder: Path) -> dict:
    from ..loading import load_module
    from ..runs import run_solve, solve_run
    from .grid import start_controls

    module = load_module(spec["problem_file"])
    run = solve_run(module, spec["problem_arg"], spec["overrides"], folder,
                    given=spec["options"], quiet=True, animation=False,
                    pictures=spec.get("pictures", False))
    run.u0 = start_controls(run.problem, spec.get("start", 0), seed=spec.get("seed", 0),
                            scale=spec.get("perturb", 0.5))
    code = run_solve(run)
    return {"exit_code": code, **summary_row(read_json(folder / SUMMARY))}


def summary_row(summary: dict) -> dict:
    """The table's figures from a solve's ``summary.json``: status, objective, keyframe
    error, iterations, evaluations, solve seconds, message and one column per miss
    (``"CenterOfMassKeyframe@20 rms_position_error"``)."""
    breakdown = summary.get("breakdown", {})
    row = {"status": summary["status_name"], "objective": summary["fun"],
           "keyframe_error": breakdown.get("keyframe_error"),
           "control_cost": breakdown.get("control_cost"), "iterations": summary["nit"],
           "evaluations": summary["nfev"],
           "solve_seconds": summary.get("timings", {}).get("wall_seconds"),
           "reason": "" if summary["success"] else summary["message"]}
    for miss in breakdown.get("misses", []):
        row.update({f"{miss['term']} {k}": v for k, v in miss.items()
                    if k not in ("term", "particles")})
    return row


def _study(spec: dict, folder: Path) -> dict:
    module, _, name = spec["function"].partition(":")
    figures = getattr(importlib.import_module(module), name)(**spec["overrides"])
    return {"status": "done", **{k: v for k, v in figures.items() if k not in spec["values"]}}


_KINDS = {"solve": _solve, "study": _study}


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, in MiB (Linux reports KiB)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024 * 1024 if sys.platform == "darwin" else 1024)


def _one_line(err) -> str:
    return " ".join(str(err).split())


class _PerThread(io.TextIOBase):
    """A stdout that each thread may point elsewhere: a worker with several threads runs
    several points at once, and each point's printout belongs in its own log."""

    def __init__(self, default):
        self.default, self.local = default, threading.local()

    def _target(self):
        return getattr(self.local, "target", None) or self.default

    def write(self, text):
        return self._target().write(text)

    def flush(self):
        self._target().flush()

    def isatty(self):
        return False


_INSTALL = threading.Lock()


@contextlib.contextmanager
def _log_to(path: Path):
    """Within the block, this thread's ``print`` goes to ``path`` (the block yields it)."""
    with _INSTALL:
        if not isinstance(sys.stdout, _PerThread):
            sys.stdout = _PerThread(sys.stdout)
    stdout = sys.stdout
    with open(path, "w") as log:
        stdout.local.target = log
        try:
            yield log
        finally:
            stdout.local.target = None
