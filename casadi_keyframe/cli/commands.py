"""The commands (``list``, ``show``, ``solve``, ``render``, ``export``, ``gradcheck``,
``study``, ``sweep``): each reads its parsed arguments, runs, and returns its exit code."""
from __future__ import annotations

import contextlib
import inspect
import shutil
import textwrap
from pathlib import Path

import numpy as np

from ..adjoints import ROUTES as GRADIENT_ROUTES
from ..loading import (check_overrides, list_problems, load_module, load_problem,
                       overrides_of, solve_defaults)
from ..optimize.deadline import now
from ..optimize.settings import settings_from
from ..runs import run_export, run_render, run_solve, solve_run
from ..runs.report import format_value
from ..saved import writable_folder
from ..saved.lock import locked
from .values import (option_items, parse_grid, parse_levels, parse_overrides,
                     parse_resolutions, parse_shooting, parse_time_steps)

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
    solve = settings_from(solve_defaults(module))
    print(f"\nsolve defaults: {solve.describe()} (--method, --option, --gradient, --maxiter, "
          "--rounds, --weight-growth, --finish, ... change them)")
    return 0


def describe_allowed(override) -> str:
    """The allowed values of an override for ``show``: its range, choices, or "any"."""
    if isinstance(override.allowed, tuple):
        text = ", ".join(override.allowed)
    else:
        text = override.allowed or ("any" if override.kind != "floats" else "any numbers")
    return text + (", or None" if override.optional else "")


def cmd_solve(args) -> int:
    from ..export import check_library

    started = now()  # --time-limit counts from here: the build and the start are the run's
    if args.from_frame is not None and args.resume is None:
        raise ValueError(f"--from-frame {args.from_frame} keeps a run's motion up to that "
                         "frame: give the run with --resume RUN")
    for fmt in args.export or ():
        check_library(fmt)  # before the solve, not after it
    module = load_module(args.problem)
    overrides = check_overrides(module, parse_overrides(args.set))  # as build gets them
    out = writable_folder(args.out, "--out") if args.out is not None else None
    shooting = parse_shooting(args.segments, option_items(args.shooting, "--shooting",
                                                          "init=blend,workers=2"),
                              args.scheduler)
    given = {**asked(args), "rounds": args.rounds, "weight_growth": args.weight_growth,
             "resolutions": parse_resolutions(module, args.resolution), "shooting": shooting,
             "homotopy": parse_levels(module, option_items(args.homotopy, "--homotopy",
                                                           "contact=3")),
             "stop": args.stop, "finish": args.finish}
    with locked(out) if out is not None else contextlib.nullcontext():  # refused before the build
        spec = solve_run(module, args.problem, overrides, out, given=given, resume=args.resume,
                         from_frame=args.from_frame,
                         quiet=args.quiet, animation=not args.no_animation,
                         exports=tuple(args.export or ()), viewer=not args.no_viewer,
                         started=started, typed=typed_options(args),
                         draw_limit=args.draw_limit)
        writable_folder(spec.out, "--out")
        return run_solve(spec)


def typed_options(args) -> tuple:
    """The options of ``solve`` as the user typed them (text as given, numbers as
    written), as ``(flag, value or None)`` pairs, but --out and --resume (the lines to type
    again add their own): what a run's "continue with" line repeats."""
    typed = []
    for flag, value in (("--set", args.set), ("--method", args.method),
                        ("--gradient", args.gradient), ("--option", args.option),
                        ("--maxiter", args.maxiter), ("--continuation", args.continuation),
                        ("--resolution", args.resolution), ("--rounds", args.rounds),
                        ("--weight-growth", args.weight_growth),
                        ("--segments", args.segments), ("--shooting", args.shooting),
                        ("--scheduler", args.scheduler), ("--homotopy", args.homotopy),
                        ("--stop", args.stop), ("--finish", args.finish),
                        ("--time-limit", args.time_limit), ("--export", args.export),
                        ("--draw-limit", args.draw_limit), ("--from-frame", args.from_frame)):
        for item in value if isinstance(value, list) else [value]:
            if item is not None:
                typed.append((flag, f"{item:g}" if isinstance(item, float) else str(item)))
    for flag, on in (("--quiet", args.quiet), ("--no-animation", args.no_animation),
                     ("--no-viewer", args.no_viewer)):
        typed += [(flag, None)] if on else []
    return tuple(typed)


def asked(args) -> dict:
    """The solve settings ``solve`` and ``sweep`` both take from the command line (None:
    not given)."""
    return {"method": args.method, "gradient": args.gradient, "maxiter": args.maxiter,
            "options": parse_overrides(args.option, "--option", "radius=0.5") or None,
            "continuation": parse_time_steps(args.continuation),
            "time_limit": args.time_limit}


def cmd_render(args) -> int:
    return run_render(args.results, animation=not args.no_animation, limit=args.draw_limit)


def cmd_export(args) -> int:
    return run_export(args.results, args.format, out=args.out)


def cmd_gradcheck(args) -> int:
    from ..studies.health_report import compare_routes, format_health, gradient_health

    prob = load_problem(args.problem, **parse_overrides(args.set))
    route = args.gradient or settings_from(solve_defaults(load_module(args.problem))).gradient
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
    from ..studies import accuracy

    if args.study == "formulations":
        return _formulations(args)
    if args.grid:
        from ..studies.sweeps import study_sweep
        from ..sweep import report

        out = writable_folder(out_folder(args, f"study-{args.study}"), "--out")
        result = study_sweep(args.study, parse_grid(args.grid), out=out,
                             overrides=parse_overrides(args.set), figure=args.figure,
                             **runner_options(args))
        report(result, out)
        return result.exit_code
    if args.study == "swap-validity":  # the map's slices, on the sweep runner
        from ..studies.swap_validity import format_swap_validity
        from ..studies.sweeps import swap_validity_map

        if args.set:
            raise ValueError("--set goes with --grid (a study grid run as a sweep)")
        out = writable_folder(out_folder(args, f"study-{args.study}"), "--out")
        study = swap_validity_map(args.quick, out=out, **runner_options(args))
        print(format_swap_validity(study))
        return study["sweep"]["exit_code"]
    if args.set or args.out is not None:
        raise ValueError("--set and --out go with --grid (a study grid run as a sweep)")
    if args.study == "gradient-accuracy":
        print(accuracy.format_gradient_accuracy(accuracy.gradient_accuracy(quick=args.quick)))
    else:
        print(accuracy.format_one_step_gap(accuracy.one_step_gap(quick=args.quick)))
    return 0


def _formulations(args) -> int:
    """``study formulations``: every formulation on every case, one process per run, kept
    in ``--out``; the table, then each run's command line and message."""
    from ..studies.accuracy import quick_mode
    from ..studies.formulations import messages, run_study, study_plan, table

    if args.grid or args.set:
        raise ValueError("--grid and --set go with the accuracy studies; the formulations "
                         "study runs its own plan (--quick: the small one)")
    out = writable_folder(out_folder(args, "study-formulations"), "--out")
    rows = run_study(*study_plan(args.quick or quick_mode()), out)
    print(table(rows))
    print(messages(rows))
    return 0


def cmd_sweep(args) -> int:
    from ..sweep import report, sweep

    grid = parse_grid(args.grid)
    out = writable_folder(out_folder(args, f"sweep-{Path(args.problem).stem}"), "--out")
    result = sweep(args.problem, grid, out=out, starts=args.starts,
                   overrides=parse_overrides(args.set), seed=args.seed, perturb=args.perturb,
                   figure=args.figure, pictures=args.pictures,
                   group_by=args.group_by.split(",") if args.group_by else None,
                   **{k: v for k, v in asked(args).items() if v is not None},
                   **runner_options(args))
    report(result, out)
    return result.exit_code


def out_folder(args, default: str):
    """``--out`` as given (an empty one is refused by the check), else ``results/DEFAULT``."""
    return Path("results") / default if args.out is None else args.out


def runner_options(args) -> dict:
    return {"workers": args.workers, "scheduler": args.scheduler, "tries": args.tries,
            "resume": args.resume, "progress": not args.quiet}


