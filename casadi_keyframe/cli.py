"""The ``casadi-keyframe`` command line: list, show, solve, render, export and gradcheck
problems; sweep a problem over a grid of overrides; print studies or run their grids."""
from __future__ import annotations

import argparse
import ast
import inspect
import shutil
import sys
import textwrap
import time
import traceback
from fractions import Fraction
from pathlib import Path

import numpy as np

from .adjoints import ROUTES as GRADIENT_ROUTES
from .cli_options import add_shooting_options, parse_levels, parse_shooting
from .export import FORMATS as EXPORT_FORMATS
from .export.alembic import BlenderError
from .saved import writable_folder
from .loading import (OverrideError, ProblemFileError, check_overrides, list_problems,
                      load_module, load_problem, overrides_of, solve_defaults)
from .optimize import METHODS
from .report import format_value
from .run import EXIT_CODES, run_export, run_render, run_solve, solve_run
from .sweep.plan import SWEEP_EXIT_CODES
from .state import SimulationError


def parse_overrides(items) -> dict:
    """``["agents=50", "cutoff=hard", "dt=1/60"]`` -> ``{"agents": 50, "cutoff": "hard",
    "dt": 0.016666666666666666}``: Python literals, fractions as floats, anything else a
    string (checked against the problem's ``build`` by :func:`loading.check_overrides`)."""
    out = {}
    for item in items or []:
        key, value = _key_value(item, "--set", "agents=50")
        out[key] = parse_value(value)
    return out


def parse_grid(items) -> dict:
    """``["weight=10,100", "dt=1/30,1/60", "x0=(0,1),(2,3)"]`` -> ``{"weight": [10, 100],
    "dt": [0.0333, 0.0167], "x0": [(0, 1), (2, 3)]}``: each value as :func:`parse_overrides`
    reads it, split at the commas outside brackets and quotes."""
    out = {}
    for item in items or []:
        key, values = _key_value(item, "--grid", "weight=10,100")
        if key in out:
            raise ValueError(f"--grid {key} is given twice: list all its values in one --grid")
        out[key] = [parse_value(v) for v in _split_top(values)]
    return out


def _key_value(item: str, option: str, example: str) -> tuple[str, str]:
    key, sep, value = item.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise ValueError(f"{option} expects KEY=VALUE such as {example}, got {item!r}")
    return key, value


def _split_top(text: str) -> list[str]:
    """``"1,(2,3),'a,b'"`` -> ``["1", "(2,3)", "'a,b'"]``; empty items dropped."""
    parts, depth, quote, current = [], 0, None, ""
    for char in text:
        if quote:
            quote = None if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char in "([{":
            depth += 1
        elif char in ")]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(current)
            current = ""
            continue
        current += char
    return [p.strip() for p in parts + [current] if p.strip()]


def _items(texts) -> list[dict]:
    """``["init=blend,workers=2", ...]`` (repeatable KEY=VALUE,... options) as dicts."""
    return [parse_overrides(_split_top(t)) for t in texts or []]


def parse_value(text: str):
    """A command-line value: a Python literal, else a fraction as a float, else the text."""
    try:
        return ast.literal_eval(text.strip())
    except (ValueError, SyntaxError, MemoryError, RecursionError):
        try:
            return float(Fraction(text.strip()))
        except (ValueError, ZeroDivisionError):
            return text


def at_least(kind, low, *, strict: bool = False):
    """An argparse type: a ``kind`` (int or float) ``>= low`` (``> low`` if ``strict``)."""
    what = (f"{'a whole number' if kind is int else 'a number'} {'>' if strict else '>='} "
            f"{low}")

    def convert(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects {what}, got {text!r}") from None
        if not (value > low if strict else value >= low) or not np.isfinite(value):
            raise argparse.ArgumentTypeError(f"expects {what}, got {text}")
        return value

    convert.__name__ = kind.__name__  # argparse names the type in some messages
    return convert


positive_int = at_least(int, 1)


def parse_time_steps(text: str | None) -> list[float] | None:
    """``"1/15,1/30,1/60"`` (fractions or decimals, seconds) -> ``[0.0667, 0.0333, 0.0167]``."""
    if not text:
        return None
    try:
        return [float(Fraction(item.strip())) for item in text.split(",")]
    except (ValueError, ZeroDivisionError):
        raise ValueError(f"--continuation expects time steps in seconds separated by commas, "
                         f"coarse to fine, e.g. 1/15,1/30,1/60; got {text!r}") from None


def parse_resolutions(module, items) -> list[dict] | None:
    """``["rows=12,cols=12", "rows=25,cols=25"]`` -> build overrides of the coarser meshes,
    each checked against the problem's ``build``; ``["none"]`` -> ``[]`` (the file's default
    meshes off); no items -> None (the file's defaults)."""
    if not items:
        return None
    if [i.strip().lower() for i in items] == ["none"]:
        return []
    out = []
    for item in items:
        pairs = _split_top(item)
        if not pairs:
            raise ValueError(f"--resolution expects KEY=VALUE,... such as rows=12,cols=12, "
                             f"got {item!r}")
        out.append(check_overrides(module, parse_overrides(pairs)))
    return out


def cmd_list(args) -> int:
    width = min(shutil.get_terminal_size((100, 24)).columns, 100)
    problems = list_problems()
    column = max(len(name) for name, _ in problems) + 2
    for name, summary in problems:
        print(textwrap.fill(summary, width, initial_indent=name.ljust(column),
                            subsequent_indent=" " * column))
    print("\n" + textwrap.fill("'casadi-keyframe show PROBLEM' prints a problem's description, "
                               "its overrides (--set NAME=VALUE) with their defaults and "
                               "ranges, and its solve defaults.", width))
    return 0


def cmd_show(args) -> int:
    module = load_module(args.problem)
    print(f"{Path(module.__file__).stem}  ({module.__file__})\n")
    print(inspect.cleandoc(module.__doc__ or "(no description)") + "\n")
    rows = [(o.name, o.type_name, format_value(o.default), describe_allowed(o))
            for o in overrides_of(module)]
    print("overrides (--set NAME=VALUE):")
    head = ("name", "type", "default", "allowed")
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(3)]
    for row in [head, *rows]:
        print("  " + "  ".join(c.ljust(w) for c, w in zip(row, widths)) + "  " + row[3])
    solve = solve_defaults(module)
    print("\nsolve defaults: " + ", ".join(f"{k} {v}" for k, v in solve.items())
          + " (--method, --gradient, --maxiter, --rounds, --weight-growth change them)")
    return 0


def describe_allowed(override) -> str:
    """The allowed values of an override for ``show``: its range, choices, or "any"."""
    if isinstance(override.allowed, tuple):
        text = ", ".join(override.allowed)
    else:
        text = override.allowed or ("any" if override.kind != "floats" else "any numbers")
    return text + (", or None" if override.optional else "")


def cmd_solve(args) -> int:
    from .export import check_library

    for fmt in args.export or ():
        check_library(fmt)  # before the solve, not after it
    module = load_module(args.problem)
    overrides = check_overrides(module, parse_overrides(args.set))  # as build gets them
    continuation = parse_time_steps(args.continuation)
    out = writable_folder(args.out, "--out") if args.out is not None else None
    shooting = parse_shooting(args.segments, _items(args.shooting), args.scheduler)
    homotopy = parse_levels(module, _items(args.homotopy))
    spec = solve_run(module, args.problem, overrides, out, method=args.method,
                     gradient=args.gradient, maxiter=args.maxiter, rounds=args.rounds,
                     weight_growth=args.weight_growth, continuation=continuation,
                     resolutions=parse_resolutions(module, args.resolution), homotopy=homotopy,
                     shooting=shooting, time_limit=args.time_limit, stop=args.stop,
                     resume=args.resume,
                     quiet=args.quiet,
                     animation=not args.no_animation, exports=tuple(args.export or ()),
                     viewer=not args.no_viewer)
    writable_folder(spec.out, "--out")
    return run_solve(spec)


def cmd_render(args) -> int:
    return run_render(args.results, animation=not args.no_animation)


def cmd_export(args) -> int:
    return run_export(args.results, args.format, out=args.out)


def cmd_gradcheck(args) -> int:
    from .health_report import compare_routes, format_health, gradient_health

    prob = load_problem(args.problem, **parse_overrides(args.set))
    route = args.gradient or solve_defaults(load_module(args.problem))["gradient"]
    names = [n.strip() for n in args.routes.split(",")] if args.routes else []
    unknown = [n for n in names if n not in GRADIENT_ROUTES]
    if unknown:
        raise ValueError(f"--routes: unknown gradient route(s) {unknown}; choose from "
                         f"{', '.join(GRADIENT_ROUTES)}")
    rng = np.random.default_rng(args.seed)
    u = prob.initial_controls() + args.scale * rng.standard_normal(prob.size)
    report = gradient_health(prob, u, route, steps=(1e4 * args.h, 1e2 * args.h, args.h),
                             directions=args.directions, seed=args.seed,
                             radius=not args.no_radius)
    where = "the start" if args.scale == 0 else f"the start + {args.scale:g} x N(0, 1)"
    print(f"{prob.name} at {where}:")
    print(format_health(report))
    if names:
        print(compare_routes(prob, u, names))
    return 0


def cmd_study(args) -> int:
    from . import studies

    if args.grid:
        from .sweep import report, study_sweep

        out = writable_folder(_out(args, f"study-{args.study}"), "--out")
        result = study_sweep(args.study, parse_grid(args.grid), out=out,
                             overrides=parse_overrides(args.set), figure=args.figure,
                             **_runner_options(args))
        report(result, out)
        return result.exit_code
    if args.study == "swap-validity":  # the map's slices, on the sweep runner
        from .swap_validity import format_swap_validity, swap_validity

        if args.set:
            raise ValueError("--set goes with --grid (a study grid run as a sweep)")
        out = writable_folder(_out(args, f"study-{args.study}"), "--out")
        study = swap_validity(args.quick, sweep={"out": out, **_runner_options(args)})
        print(format_swap_validity(study))
        return study["sweep"]["exit_code"]
    if args.set or args.out is not None:
        raise ValueError("--set and --out go with --grid (a study grid run as a sweep)")
    if args.study == "gradient-accuracy":
        print(studies.format_gradient_accuracy(studies.gradient_accuracy(quick=args.quick)))
    else:
        print(studies.format_one_step_gap(studies.one_step_gap(quick=args.quick)))
    return 0


def cmd_sweep(args) -> int:
    from .sweep import report, sweep

    grid = parse_grid(args.grid)
    out = writable_folder(_out(args, f"sweep-{Path(args.problem).stem}"), "--out")
    result = sweep(args.problem, grid, out=out, starts=args.starts,
                   overrides=parse_overrides(args.set), seed=args.seed, perturb=args.perturb,
                   figure=args.figure, pictures=args.pictures,
                   group_by=args.group_by.split(",") if args.group_by else None,
                   continuation=parse_time_steps(args.continuation),
                   **{k: getattr(args, k) for k in ("method", "gradient", "maxiter",
                                                    "time_limit")},
                   **_runner_options(args))
    report(result, out)
    return result.exit_code


def _out(args, default: str):
    """``--out`` as given (an empty one is refused by the check), else ``results/DEFAULT``."""
    return Path("results") / default if args.out is None else args.out


def _runner_options(args) -> dict:
    return {"workers": args.workers, "scheduler": args.scheduler, "tries": args.tries,
            "resume": args.resume, "progress": not args.quiet}


def _add_runner_options(p) -> None:
    """The cluster and resume options ``sweep`` and ``study --grid`` share."""
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="use the running Dask cluster whose scheduler is at ADDRESS (e.g. "
                        "tcp://10.0.0.5:8786) instead of a local one; its workers need this "
                        "library and a filesystem shared with --out")
    p.add_argument("--tries", type=positive_int, default=3, metavar="N",
                   help="times a point is started before it is reported failed when the "
                        "workers running it die (local cluster; default 3)")
    p.add_argument("--resume", action="store_true",
                   help="continue a sweep in --out: points already complete are skipped")
    p.add_argument("--quiet", action="store_true", help="no progress display")


def _add_sweep_parser(sub) -> None:
    w = sub.add_parser("sweep", help="solve a problem at every combination of some overrides "
                                     "(and from several starts), on a Dask cluster",
                       epilog=SWEEP_EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    w.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    w.add_argument("--grid", action="append", required=True, metavar="KEY=V1,V2,...",
                   help="values of a build() argument to sweep; several --grid make a "
                        "Cartesian product")
    w.add_argument("--starts", type=positive_int, default=1, metavar="K",
                   help="starts per grid point: the problem's own and K-1 perturbed ones")
    w.add_argument("--perturb", type=at_least(float, 0), default=0.5, metavar="SIGMA",
                   help="rms of a perturbed start: m/s^2 times each particle's mass for "
                        "per-step forces, m/s for initial velocities (default 0.5)")
    w.add_argument("--seed", type=at_least(int, 0), default=0,
                   help="seed of the perturbed starts")
    w.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a build() argument at every point")
    w.add_argument("--method", choices=list(METHODS))
    w.add_argument("--gradient", choices=GRADIENT_ROUTES)
    w.add_argument("--maxiter", type=positive_int, help="iteration limit of each point")
    w.add_argument("--continuation", metavar="DT,DT,...", help="as for solve")
    w.add_argument("--time-limit", type=at_least(float, 0, strict=True), metavar="SECONDS",
                   help="wall-time limit of each point's search")
    w.add_argument("--figure", default="objective",
                   help="what ranks the points and is plotted: objective (default), "
                        "keyframe_error, control_cost, iterations, evaluations, seconds")
    w.add_argument("--group-by", metavar="KEY,KEY",
                   help="name the best point of each combination of these swept keys "
                        "(default: of each grid point with --starts > 1, else overall)")
    w.add_argument("--pictures", action="store_true",
                   help="draw each point's keyframes.png and convergence.png (default: "
                        "results only; 'casadi-keyframe render POINT_FOLDER' draws them)")
    w.add_argument("--out", help="output folder (default results/sweep-PROBLEM)")
    _add_runner_options(w)
    w.set_defaults(func=cmd_sweep)


def _output_options(s) -> None:
    """``solve``'s options for what it writes."""
    s.add_argument("--out", help="output folder (default results/PROBLEM)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--no-animation", action="store_true", help="skip the GIF")
    s.add_argument("--no-viewer", action="store_true",
                   help="skip viewer.html, the interactive viewer (needs plotly)")
    s.add_argument("--export", action="append", metavar="FORMAT", choices=EXPORT_FORMATS,
                   help="also export the result: usd, pc2, obj, html or abc (repeatable; see "
                        "'casadi-keyframe export')")


def _export_parser(sub) -> None:
    """The ``export`` command."""
    e = sub.add_parser("export", help="write a saved result as USD, a PC2 point cache, an OBJ "
                                      "sequence or the HTML viewer")
    e.add_argument("results", help="results folder (with result.npz), or the result.npz")
    e.add_argument("--format", action="append", required=True, choices=EXPORT_FORMATS,
                   help="usd: NAME.usd, one stage (needs casadi_keyframe[usd]); pc2: NAME.pc2 "
                        "and its rest mesh NAME_rest.obj (Blender's Mesh Cache modifier); "
                        "obj: obj/NAME_0000.obj ... one per frame; html: viewer.html (needs "
                        "casadi_keyframe[viewer]); abc: NAME.abc, Alembic of a cloth (needs "
                        "Blender: the bpy module or a blender binary); repeatable")
    e.add_argument("--out", help="output folder (default: the results folder)")
    e.set_defaults(func=cmd_export)


def _solve_parser(sub) -> None:
    """The ``solve`` command's arguments."""
    s = sub.add_parser("solve", help="optimise a problem and write results and pictures",
                       epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    s.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a build() argument")
    s.add_argument("--method", choices=list(METHODS))
    s.add_argument("--gradient", choices=GRADIENT_ROUTES,
                   help="gradient route (default: the problem's SOLVE, else 'adjoint'): "
                        "'adjoint' the exact hand adjoint, 'swapped' the paper's approximate "
                        "one (cloth), 'casadi' CasADi reverse mode (small systems), 'fd' "
                        "finite differences ('exact' is a deprecated name of 'casadi')")
    s.add_argument("--maxiter", type=positive_int, help="iteration limit (per stage with --continuation)")
    s.add_argument("--continuation", metavar="DT,DT,...",
                   help="solve at these time steps first, coarse to fine (e.g. 1/15,1/30,1/60); "
                        "the problem's dt ends the list")
    s.add_argument("--resolution", action="append", metavar="KEY=VALUE,...",
                   help="solve first on this coarser mesh of the same cloth, e.g. "
                        "rows=12,cols=12 (repeat, coarse to fine; 'none': not the problem "
                        "file's default meshes); the controls are carried to each finer mesh")
    s.add_argument("--rounds", type=int, metavar="N",
                   help="augmented-Lagrangian rounds: after each, the keyframes aim past their "
                        "target by the miss left (hard keyframes; --maxiter per round)")
    s.add_argument("--weight-growth", type=float, metavar="G",
                   help="multiply the keyframe weights by G per round (a penalty schedule)")
    add_shooting_options(s, at_least(int, 1))
    s.add_argument("--stop", choices=("goal", "method"),
                   help="when the search is done: 'goal' once every keyframe is within its "
                        "tolerance (the default where the problem declares tolerances), "
                        "'method' at the method's own test; either way it converged (exit 0) "
                        "only with every keyframe within its tolerance"),
    _output_options(s)
    s.add_argument("--time-limit", type=at_least(float, 0, strict=True), metavar="SECONDS",
                   help="stop the search after this wall time (over all stages and rounds); "
                        "the best result is written, exit code 3")
    s.add_argument("--resume", metavar="DIR_OR_NPZ",
                   help="start from a run's controls: a results folder (the newer of its "
                        "checkpoint.npz and result.npz) or either file; same problem and --set")
    s.set_defaults(func=cmd_solve)


def _gradcheck_parser(sub) -> None:
    """The ``gradcheck`` command's arguments."""
    g = sub.add_parser("gradcheck", help="a gradient route's health at a point: backward "
                                          "growth, dot-product test, central differences, "
                                          "linearity radius, and a verdict")
    g.add_argument("problem")
    g.add_argument("--set", action="append", metavar="KEY=VALUE")
    g.add_argument("--gradient", choices=GRADIENT_ROUTES,
                   help="the route checked (default: the problem's SOLVE, else 'adjoint'); "
                        "an approximate one is compared with the exact adjoint")
    g.add_argument("--routes", help="also compare these comma-separated routes' gradients; "
                                    "the last is the reference (e.g. adjoint,casadi)")
    g.add_argument("--directions", type=at_least(int, 0), default=1,
                   help="random directions for central differences (beside the gradient's)")
    g.add_argument("--h", type=at_least(float, 0, strict=True), default=1e-6,
                   help="the smallest central-difference step (also 100x and 10000x it), "
                        "times max(|u|, 1)")
    g.add_argument("--scale", type=at_least(float, 0), default=0.0,
                   help="check at the problem's start plus this rms of random controls "
                        "(default 0: at the start)")
    g.add_argument("--no-radius", action="store_true",
                   help="skip the linearity radius (a ladder of simulations)")
    g.add_argument("--seed", type=int, default=0)
    g.set_defaults(func=cmd_gradcheck)


def _study_parser(sub) -> None:
    """The ``study`` command's arguments (and its grid on the sweep runner)."""
    st = sub.add_parser("study", help="print an accuracy study (the notebooks' tables), or "
                                      "run a grid of it as a sweep (--grid)",
                        epilog=SWEEP_EXIT_CODES + "\n\nexample: casadi-keyframe study "
                        "gradient-accuracy --grid dt=1/30,1/60,1/120 --grid stretch=50,500",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    st.add_argument("study", choices=("gradient-accuracy", "integrator-accuracy",
                                      "swap-validity"))
    st.add_argument("--quick", action="store_true", help="small sizes (as CASADI_KEYFRAME_QUICK=1)")
    st.add_argument("--grid", action="append", metavar="KEY=V1,V2,...",
                    help="run the study at every combination of these values on the sweep "
                         "runner (gradient-accuracy: dt, horizon, stretch, amplitude, seed; "
                         "integrator-accuracy: dt, stretch, rows, seed; swap-validity: "
                         "contact, collision, stiffness, dt, amplitude, horizon, speed, "
                         "damping, rows, solve, maxiter, seed; without --grid it runs its "
                         "whole map on the runner)")
    st.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="a fixed value for every point of the grid")
    st.add_argument("--figure", help="the figure ranked and plotted (gradient-accuracy: "
                                     "relative_error; integrator-accuracy: gap_x or gap_v; "
                                     "swap-validity: relative_error, growth_swapped, cosine)")
    st.add_argument("--out", help="output folder (default results/study-STUDY)")
    _add_runner_options(st)
    st.set_defaults(func=cmd_study)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="casadi-keyframe", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the problem files").set_defaults(func=cmd_list)
    sh = sub.add_parser("show", help="a problem's description, overrides (type, default, range) "
                                     "and solve defaults")
    sh.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    sh.set_defaults(func=cmd_show)

    _solve_parser(sub)

    r = sub.add_parser("render", help="draw a saved run's pictures again (convergence.png, "
                                      "keyframes.png, animation.gif) without solving")
    r.add_argument("results", help="results folder (result.npz and summary.json, or only "
                                    "checkpoint.npz), or one of those .npz files")
    r.add_argument("--no-animation", action="store_true", help="skip the GIF")
    r.set_defaults(func=cmd_render)

    _export_parser(sub)
    _gradcheck_parser(sub)
    _study_parser(sub)
    _add_sweep_parser(sub)
    debug = "print the whole traceback with an error (the library's own lines included)"
    p.add_argument("--debug", action="store_true", help=debug)
    for command in sub.choices.values():  # also after the command, where users type it
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help=debug)
    return p


def main(argv=None) -> int:
    """Run a command: 0 on success, 1 when the simulation fails, 2 on bad input (a message,
    never a traceback; ``--debug`` adds the traceback)."""
    args = build_parser().parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        return args.func(args)
    except OverrideError as err:
        _error(err, debug, f"\n  'casadi-keyframe show {err.problem}' lists the overrides "
                           "with their types, defaults and ranges")
        return 2
    except SimulationError as err:
        text = " ".join(str(err).split())
        text = text if "simulation" in text else f"the simulation failed: {text}"
        fix = "" if "reduce" in text else "; reduce dt (--set dt=...) or the forces"
        _error(err, debug, text=text + fix)
        return 1
    except ProblemFileError as err:
        _error(err, debug, "" if debug else "\n  (--debug shows the whole traceback)")
        return 2
    except (ValueError, TypeError, FileNotFoundError, ImportError) as err:
        _error(err, debug)
        return 2
    except BlenderError as err:  # an export through Blender that Blender did not finish
        _error(err, debug)
        return 1


def _error(err, debug: bool, more: str = "", *, text: str | None = None) -> None:
    """``error: MESSAGE`` on stderr (with ``--debug``, the traceback first)."""
    if debug:
        traceback.print_exception(err)
    print(f"error: {err if text is None else text}{more}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
