"""The search itself, old against new: each case solved as a user gets it (the problem file's
``SOLVE``: its stages, rounds and gradient route) with each method, through the command line's
own ``solve`` path, one BLAS thread, CPU time.

Per run: the start's and the result's keyframe misses (mm rms; a region: % inside), the
largest spring stretch, the effort (rms and peak control acceleration per particle, m/s^2:
control force / particle mass), iterations, evaluations, CPU seconds and the exit code.
``--radius`` adds ``gradcheck``'s linearity radius (``gradient_health`` on the route ``solve``
used; 0: below its smallest resolvable step) at the start and the result, each over
``max(|u|, 1)`` (its steps' scale), both verdicts and their CPU seconds, all on the problem
the result belongs to (a coarse-to-fine file's finest mesh; under multiple shooting the
single-shooting objective) from that problem's own start.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/search.py \\
        --cases mesh12-none,mesh12-track --methods lbfgsb,gauss-newton

``--cases`` picks from :data:`CASES` (default: all but :data:`SLOW`; every shipped problem
at its defaults, ``mesh12`` being ``mesh_keyframes``'; the README's walkthrough reads a
30 x 30 sheet and its targets written into a temporary folder first); ``--set KEY=VALUE``,
``--maxiter``, ``--time-limit``, ``--segments``, ``--shooting`` and ``--finish`` go to every
run (``--finish none``: the search without the problem file's finish).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from casadi_keyframe.cli.values import option_items, parse_overrides, parse_shooting  # noqa: E402
from casadi_keyframe.saved import read_run  # noqa: E402
from casadi_keyframe.loading import load_module  # noqa: E402
from casadi_keyframe.runs import run_solve, solve_run  # noqa: E402
from casadi_keyframe.scenes.mesh_targets import write_sheet_and_targets  # noqa: E402
from casadi_keyframe.studies.health_report import gradient_health  # noqa: E402


def walkthrough(folder: Path, guess: str | None = None) -> dict:
    """The README's mesh walkthrough's overrides (30 x 30 sheet from OBJ, wave at frame 40,
    fold at frame 80, pinned at 0 and 29), its files written into ``folder`` once."""
    if not (folder / "sheet.obj").is_file():
        write_sheet_and_targets(folder, 30, 30)
    out = {"cloth": str(folder / "sheet.obj"), "pins": (0, 29),
           "keyframes": f"40:{folder / 'wave.obj'},80:{folder / 'fold.obj'}"}
    return out if guess is None else {**out, "guess": guess}


CASES = {
    "walkthrough": ("mesh_keyframes", lambda f: walkthrough(f)),
    "walkthrough-track": ("mesh_keyframes", lambda f: walkthrough(f, "track")),
    "walkthrough-none": ("mesh_keyframes", lambda f: walkthrough(f, "none")),
    "mesh12": ("mesh_keyframes", lambda f: {}),
    "mesh12-none": ("mesh_keyframes", lambda f: {"guess": "none"}),
    "mesh12-track": ("mesh_keyframes", lambda f: {"guess": "track"}),
    "cloth_shapes": ("cloth_shapes", lambda f: {}),
    "cloth_arch": ("cloth_arch", lambda f: {}),
    "flock_shapes": ("flock_shapes", lambda f: {}),
    "flock_path": ("flock_path", lambda f: {}),
    "flock_race": ("flock_race", lambda f: {}),
    "cloth_toss": ("cloth_toss", lambda f: {}),
    "cape_blend": ("cape_blend", lambda f: {}),
    "cape-passive": ("cape_blend", lambda f: {"guess": "passive"}),
}
SLOW = ("cape-passive",)  # run by name only: multiple shooting from zero forces


def misses(breakdown) -> str:
    """Each keyframe's miss: mm rms (a centre: mm), a region: % of its agents inside."""
    out = []
    for m in breakdown["misses"]:
        if "rms_position_error" in m:
            out.append(f"{1e3 * m['rms_position_error']:.1f}")
        elif "position_error" in m:
            out.append(f"{1e3 * m['position_error']:.1f}")
        elif "fraction_inside" in m:
            out.append(f"{100 * m['fraction_inside']:.0f}%")
    return ",".join(out)


def effort(prob, u) -> tuple[float, float]:
    """rms and peak control acceleration per particle (m/s^2, ``ControlProblem.effort``);
    NaN for controls that are not forces."""
    found = prob.effort(u)
    if found is None:
        return float("nan"), float("nan")
    return found["rms_acceleration"], found["peak_acceleration"]


def stretch(breakdown) -> float:
    return breakdown.get("physical", {}).get("max_stretch", float("nan"))


def linearity(prob, route, u) -> dict:
    """gradcheck's report of ``route`` at ``u``: its linearity radius, that over
    ``max(|u|, 1)`` and its verdict."""
    report = gradient_health(prob, u, route)
    return {"radius": report.radius, "verdict": report.verdict,
            "relative": report.radius / max(float(np.linalg.norm(u)), 1.0)}


def run_case(name, method, folder, args) -> dict:
    problem, overrides = CASES[name]
    overrides = {**overrides(folder), **parse_overrides(args.set)}
    module = load_module(problem)
    out = Path(tempfile.mkdtemp(prefix=f"search_{name}_{method}_"))
    extra = {} if method in (None, "file") else {"method": method}
    if args.finish is not None:
        extra["finish"] = args.finish
    shooting = parse_shooting(args.segments, option_items(args.shooting, "--shooting",
                                                          "place=growth"), None)
    given = {"maxiter": args.maxiter, "shooting": shooting, "time_limit": args.time_limit,
             **extra}
    spec = solve_run(module, problem, overrides, out, given=given, quiet=True,
                     pictures=False, animation=False, viewer=False)
    prob = spec.problem
    start_u = prob.initial_controls()
    start = prob.breakdown(start_u)
    printed = io.StringIO()
    t = time.process_time()
    with contextlib.redirect_stdout(printed):
        code = run_solve(spec)
    cpu = time.process_time() - t
    run = read_run(out)
    u, summary = run["u"], json.loads((out / "summary.json").read_text())
    end = prob.breakdown(u)
    rms, peak = effort(prob, u)
    found = {"case": name, "method": spec.settings.method, "start": misses(start),
             "end": misses(end), "stretch": stretch(end), "rms": rms, "peak": peak,
             "start_rms": effort(prob, start_u)[0], "nit": summary["nit"],
             "nfev": summary["nfev"], "cpu": cpu, "exit": code,
             "message": summary.get("message", "")}
    if args.radius:
        t = time.process_time()
        route = spec.settings.gradient.name
        first = linearity(prob, route, start_u)  # the result may be the start
        found["at"] = [first, first if np.array_equal(u, start_u) else
                       linearity(prob, route, u)]
        found["radius_cpu"], found["route"] = time.process_time() - t, route
    return found


HEADER = (f"{'case':18s} {'method':12s} {'start mm':>13s} {'end mm':>13s} {'stretch':>7s} "
          f"{'acc rms':>8s} {'peak':>8s} {'iter':>5s} {'evals':>5s} {'CPU s':>7s} exit")


RADIUS = (f" {'r start':>8s} {'r/|u|':>8s} {'r end':>8s} {'r/|u|':>8s} {'verdicts':17s} "
          f"{'CPU s':>6s}")


def row(r) -> str:
    out = (f"{r['case']:18s} {r['method']:12s} {r['start']:>13s} {r['end']:>13s} "
           f"{r['stretch']:7.3f} {r['rms']:8.1f} {r['peak']:8.1f} {r['nit']:5d} "
           f"{r['nfev']:5d} {r['cpu']:7.1f} {r['exit']:4d}")
    if "at" not in r:
        return out
    start, end = r["at"]
    return (out + f" {start['radius']:8.1e} {start['relative']:8.1e} {end['radius']:8.1e} "
            f"{end['relative']:8.1e} {start['verdict'] + '/' + end['verdict']:17s} "
            f"{r['radius_cpu']:6.1f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default=",".join(c for c in CASES if c not in SLOW))
    parser.add_argument("--methods", default="lbfgsb,gauss-newton")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--maxiter", type=int, default=None)
    parser.add_argument("--segments", type=int, default=None,
                        help="multiple shooting's segments for every run (1: none)")
    parser.add_argument("--shooting", action="append", metavar="KEY=VALUE,...",
                        help="multiple shooting's options, as solve's --shooting")
    parser.add_argument("--time-limit", type=float, default=None)
    parser.add_argument("--finish", default=None,
                        help="solve's --finish for every run ('none': the search alone)")
    parser.add_argument("--messages", action="store_true", help="print each run's message")
    parser.add_argument("--radius", action="store_true",
                        help="the linearity radius and gradcheck's verdict at start and end")
    args = parser.parse_args(argv)
    folder = Path(tempfile.gettempdir()) / "casadi_keyframe_walkthrough"
    print(HEADER + (RADIUS if args.radius else ""), flush=True)
    for name in args.cases.split(","):
        if name not in CASES:
            parser.error(f"unknown case {name!r}; choose from {', '.join(CASES)}")
        for method in args.methods.split(","):
            r = run_case(name, method, folder, args)
            print(row(r), flush=True)
            if args.messages:
                route = f" (radius on route {r['route']})" if "route" in r else ""
                print(f"    {r['message']}{route}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
