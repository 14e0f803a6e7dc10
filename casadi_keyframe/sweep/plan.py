"""Sweeps as a whole: check the grid, plan the points (skipping complete ones on resume),
run them on the cluster, then write the table, the plot and ``sweep.json``.

Everything about the input is checked before any worker starts: the grid's keys and
values like ``--set`` overrides (:func:`..loading.check_overrides`, every point's full set),
the figure, the output folder.  ``sweep.json`` names the best point of each group (the
lowest figure; groups are the combinations of the ``group_by`` keys), the counts and
where the tables are.
"""
from __future__ import annotations

import hashlib
import json
import signal
import time
import types
from dataclasses import dataclass, field
from pathlib import Path

from ..saved import FileDamaged, writable_folder
from ..interrupts import NAMES, catching, handled
from ..saved import write_json
from ..loading import OverrideError, check_overrides, load_module, resolve
from ..optimize.outcome import INTERRUPTED
from ..runs import exit_code
from .grid import points
from .progress import Progress, format_seconds
from .runner import check_workers, connect, run_specs
from .table import best_per_group, value_of, write_tables
from .tasks import ERROR, read_row
from .tasks import failed as is_failed

POINTS, SUMMARY = "points", "sweep.json"
FIGURES = ("objective", "keyframe_error", "control_cost", "iterations", "evaluations",
           "seconds", "solve_seconds")
RUNNER_OPTIONS = ("workers", "scheduler", "tries", "resume", "progress", "timeout")
SWEEP_EXIT_CODES = """\
exit codes:
  0    every point solved (converged, or stopped at --maxiter / --time-limit: the table's
       status says which)
  1    at least one point failed (no result after --tries attempts, an error, or the
       search failed): the table's reason column says why; the other points are written
  2    bad input (problem, grid, overrides, options, scheduler address, --out)
  130  interrupted by Ctrl-C before every point finished: the finished points are on
       disk, continue with --resume (a signal after every point finished changes nothing)
  143  stopped by SIGTERM; as 130"""


@dataclass
class Plan:
    """What a sweep runs: the specs of the points to solve, the folder, the swept keys, the
    figure to rank and plot by, the keys that group points for "best"."""

    specs: list
    out: Path
    keys: list
    figure: str
    group_by: list
    about: dict = field(default_factory=dict)  # what sweep.json records of the input


@dataclass
class SweepResult:
    """A finished (or stopped) sweep: every point's row (from disk, earlier runs included),
    the best per group, the files written, the points failed or never run, and the exit
    code (see :data:`SWEEP_EXIT_CODES`)."""

    rows: list
    best: list
    files: list
    failed: list
    missing: list
    exit_code: int
    summary: dict


def sweep(problem, grid: dict, *, out, starts: int = 1, overrides: dict | None = None,
          seed: int = 0, perturb: float = 0.5, figure: str = "objective", group_by=None,
          pictures: bool = False, **options) -> SweepResult:
    """Solve ``problem`` (a name or a file) at every combination of ``grid``'s values
    (``{"weight": [10, 100], "alpha": [1e-4, 1e-3]}``) on top of ``overrides``, from
    ``starts`` starts each (start 0 the problem's own, the others perturbed by ``perturb``
    m/s^2 rms, seeded by ``(seed, start)``), each point as ``casadi-keyframe solve`` would,
    into ``out/points/NAME/``.  ``options`` are the solve's settings (any of
    :data:`~casadi_keyframe.optimize.settings.REQUEST`: ``method``, ``options``,
    ``gradient``, ``maxiter``, ``rounds``, ...; each point's request is made from them and
    its file's ``SOLVE`` as ``casadi-keyframe solve`` makes it) and the runner's
    (``workers``, ``scheduler``, ``tries``, ``resume``, ``progress``)."""
    runner = {k: options.pop(k) for k in RUNNER_OPTIONS if k in options}
    check_search_options(options)
    module = load_module(problem)
    overrides = dict(overrides or {})
    grid = check_grid(module, grid, overrides)
    if figure not in FIGURES:
        raise ValueError(f"--figure {figure!r}: choose one of {', '.join(FIGURES)}")
    file = str(resolve(module.__file__).resolve())
    base = {"kind": "solve", "problem_file": file, "problem_arg": str(problem),
            "options": options, "seed": seed, "perturb": perturb, "pictures": pictures,
            "source": hashlib.sha1(Path(file).read_bytes()).hexdigest()}
    specs = []
    for point in points(grid, starts):
        full = check_overrides(module, {**overrides, **point.values})
        specs.append({**base, "overrides": full, "values": point.values,
                      "start": point.start, "name": point.name, "label": point.label})
    keys = list(grid)
    default = keys if starts > 1 else []  # the best start of each grid point, or the best
    group_by = check_group_by(default if group_by is None else group_by, keys)
    about = {"problem": Path(file).stem, "problem_file": file, "grid": grid, "starts": starts,
             "overrides": overrides, "seed": seed, "perturb": perturb, "options": options}
    return run_plan(Plan(specs, Path(out), keys, figure, group_by, about), **runner)


def check_search_options(options: dict) -> None:
    """Refuse a setting the solve does not take or a value it refuses (an unknown method,
    route or method option), here rather than in every point on the workers."""
    from ..optimize.settings import REQUEST, settings_from

    unknown = sorted(set(options) - set(REQUEST))
    if unknown:
        raise TypeError(f"sweep() got unknown option(s) {', '.join(unknown)}; the solve "
                        f"takes {', '.join(REQUEST)}, the runner {', '.join(RUNNER_OPTIONS)}")
    settings_from(None, options)


def check_grid(module, grid: dict, overrides: dict) -> dict:
    """The grid with its values converted as ``build`` gets them (``1`` to ``1.0`` for a
    float), so typing a value twice is caught; refuses a key that is also a ``--set``
    override, or a key or value ``build`` would refuse (named as
    :func:`..loading.check_overrides` names it)."""
    both = sorted(set(grid) & set(overrides))
    if both:
        raise ValueError(f"{', '.join(both)} given both in --grid and --set: keep one")
    out = {}
    for key, values in grid.items():
        try:
            out[key] = [check_overrides(module, {key: value})[key] for value in values]
        except OverrideError as err:
            raise OverrideError(f"--grid {key}: {err}", err.problem) from None
    return out


def check_group_by(group_by, keys) -> list:
    """``group_by`` as a list, each a swept key (ValueError otherwise)."""
    unknown = sorted(set(group_by) - set(keys))
    if unknown:
        raise ValueError(f"--group-by {', '.join(unknown)}: not a swept key; choose among "
                         f"{', '.join(keys) or '(none: the grid is empty)'}")
    return list(group_by)


def run_plan(plan: Plan, *, workers: int | None = None, scheduler: str | None = None,
             tries: int = 3, resume: bool = False, progress: bool = True,
             timeout: float = 10.0) -> SweepResult:
    """Run the plan's points not already complete, then write the table, the plot and
    ``sweep.json``; the :class:`SweepResult`.  ``plan.out`` that cannot be written is
    refused (ValueError naming ``out=``) before any point starts."""
    folder = writable_folder(plan.out, "out=") / POINTS
    folder.mkdir(parents=True, exist_ok=True)
    for spec in plan.specs:
        spec["folder"] = str((folder / spec["name"]).resolve())
        spec["id"] = spec_id(spec)
    todo, stale = _todo(plan.specs, resume)
    started, signum = time.monotonic(), None
    if stale and progress:
        print(f"sweep: {stale} finished point(s) were solved with other settings: solving "
              "them again")
    if todo:
        signum = _solve_points(todo, folder, skipped=len(plan.specs) - len(todo),
                               progress=progress, workers=workers, scheduler=scheduler,
                               tries=tries, timeout=timeout)
    elif progress:
        print(f"sweep: all {len(plan.specs)} points are complete already")
    where = scheduler or ("local, one worker per core" if workers is None else
                          f"local, {workers} worker{'s' * (workers != 1)}")
    return _finish(plan, signum, time.monotonic() - started, where)


def _solve_points(todo, folder, *, skipped, progress, workers, scheduler, tries, timeout):
    """Solve the points ``todo`` on the cluster; the signal that stopped the sweep, or None.

    SIGINT and SIGTERM are caught throughout (:func:`..interrupts.catching`): one while the
    cluster starts, runs or closes stops the sweep, and the cluster is closed whole even
    when a second one comes (it is raised after the close)."""
    signum = None
    with catching():
        try:
            with connect(workers=workers, scheduler=scheduler, tries=tries,
                         timeout=timeout) as client:
                check_workers(client, [folder.resolve(), *_files(todo)])
                shown = Progress(len(todo), skipped=skipped, enabled=progress)
                _, signum = run_specs(client, todo, progress=shown,
                                      tries=None if scheduler else tries)
                shown.close()
        except KeyboardInterrupt as err:  # while the cluster starts or closes
            signum = signum or getattr(err, "signum", signal.SIGINT)
        handled()  # acted on: the table and the plot are still written
    return signum


def _files(specs) -> set:
    """The problem files the points load (none for a study)."""
    return {s["problem_file"] for s in specs if "problem_file" in s}


def spec_id(spec: dict) -> str:
    """A hash of what a point solves (file contents, overrides, options, start): a row with
    another id was solved differently and does not count as this point's result."""
    what = {k: v for k, v in spec.items()
            if k not in ("folder", "id", "label", "name", "pictures", "problem_arg")}
    return hashlib.sha1(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _todo(specs, resume: bool):
    """The specs to run and how many finished points are re-run for other settings; without
    ``resume`` a folder that already holds points is refused."""
    rows, damaged = [], []
    for spec in specs:
        try:
            rows.append(read_row(spec["folder"]))
        except FileDamaged as err:  # a point cut short as its row was written elsewhere
            rows.append(None)
            damaged.append(err)
    if not resume and (any(rows) or damaged):
        raise ValueError(f"{Path(specs[0]['folder']).parent.parent} already holds a sweep's "
                         "points: give --resume to continue it (finished points are skipped) "
                         "or choose another --out")
    complete = [r is not None and r.get("status") != ERROR and r.get("spec_id") == s["id"]
                for r, s in zip(rows, specs)]
    stale = sum(r is not None and r.get("status") != ERROR and r.get("spec_id") != s["id"]
                for r, s in zip(rows, specs))
    for err in damaged:
        print(f"sweep: {err}")
    return [s for s, ok in zip(specs, complete) if not ok], stale


def _finish(plan: Plan, signum, seconds: float, where: str) -> SweepResult:
    """Collect every point's row from disk and write the table, the plot and sweep.json."""
    from ..render.sweep import sweep_plot

    rows, missing = [], []
    for spec in plan.specs:
        row = _row_or_none(spec["folder"])
        if row is None or row.get("spec_id") != spec["id"]:
            missing.append(spec["name"])
        else:
            rows.append(row)
    files = write_tables(rows, plan.out, plan.keys) if rows else []
    drawn = [r for r in rows if value_of(r, plan.figure) is not None]
    picture = sweep_plot({key: [r.get(key) for r in drawn] for key in plan.keys},
                         [value_of(r, plan.figure) for r in drawn], plan.figure,
                         plan.out / "sweep.png")
    files += [picture] if picture else []
    failed = [r["point"] for r in rows if is_failed(r)]
    best = best_per_group(rows, plan.figure, plan.group_by)
    # a signal after every point finished loses nothing: the sweep is complete
    code = (exit_code(INTERRUPTED, signum) if signum and missing
            else 1 if failed or missing else 0)
    summary = {**plan.about, "figure": plan.figure, "group_by": plan.group_by,
               "points": len(plan.specs), "complete": len(rows) - len(failed),
               "failed": failed, "missing": missing, "best": best, "cluster": where,
               "seconds": seconds, "exit_code": code, "files": [str(f) for f in files],
               "signal_after_complete": NAMES.get(signum, signum) if signum and not missing
               else None}
    write_json(plan.out / SUMMARY, summary)
    return SweepResult(rows, best, files + [plan.out / SUMMARY], failed, missing, code,
                       summary)


def _row_or_none(folder) -> dict | None:
    """A point's row, or None when it has none or a damaged one (the point is missing)."""
    try:
        return read_row(folder)
    except FileDamaged:
        return None


def report(result: SweepResult, out) -> None:
    """Print where the table is, the best point of each group, the failures and, after an
    interrupt or failures, how to continue."""
    s = result.summary
    print(f"sweep of {s.get('problem', s.get('study'))}: {s['complete']} of {s['points']} "
          f"points complete, {len(s['failed'])} failed, {len(s['missing'])} not run "
          f"({format_seconds(s['seconds'])}, {s['cluster']})")
    if s.get("signal_after_complete"):
        print(f"  {s['signal_after_complete']} came after every point had finished: the sweep "
              "is complete")
    for path in result.files:
        print(f"  wrote {path}")
    for b in result.best[:20]:
        group = " ".join(f"{k}={v}" for k, v in b["group"].items()) or "all points"
        print(f"  best ({group}): {b['point']}, {s['figure']} {b[s['figure']]:.6g}  {b['path']}")
    for row in result.rows:
        if row["point"] in s["failed"]:
            print(f"  FAILED {row['point']}: {row.get('reason', '')}")
    if s["missing"] or s["failed"]:
        print(f"  continue with the same command and --resume (--out {out}): complete "
              "points are skipped")


def study_module(name: str, function, ranges: dict) -> types.ModuleType:
    """A module with ``build = function`` and ``RANGES``, so a study's grid is checked like
    a problem file's overrides."""
    module = types.ModuleType(name)
    module.build, module.RANGES = function, ranges
    module.__file__ = f"{name}.py"  # what check_overrides names it by
    return module
