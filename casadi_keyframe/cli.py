"""The ``casadi-keyframe`` command line: list, show, solve, render, export and gradcheck
problems; print studies."""
from __future__ import annotations

import argparse
import ast
import inspect
import shutil
import sys
import tempfile
import textwrap
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

from .adjoints import ROUTES as GRADIENT_ROUTES
from .export import FORMATS as EXPORT_FORMATS
from .loading import (OverrideError, build_problem, check_overrides, list_problems,
                      load_module, load_problem, overrides_of, resolve, solve_defaults)
from .run import EXIT_CODES, SolveRun, run_export, run_render, run_solve
from .state import SimulationError


def parse_overrides(items) -> dict:
    """``["agents=50", "cutoff=hard", "dt=1/60"]`` -> ``{"agents": 50, "cutoff": "hard",
    "dt": 0.016666666666666666}``: Python literals, fractions as floats, anything else a
    string (checked against the problem's ``build`` by :func:`loading.check_overrides`)."""
    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise ValueError(f"--set expects KEY=VALUE such as agents=50, got {item!r}")
        try:
            out[key] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError, MemoryError, RecursionError):
            try:
                out[key] = float(Fraction(value.strip()))
            except (ValueError, ZeroDivisionError):
                out[key] = value
    return out


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


def ensure_writable(folder) -> Path:
    """Create ``folder`` (and its parents) and check a file can be written in it, so a bad
    ``--out`` is refused before the build and the solve, not at the first checkpoint."""
    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as err:
        blocker = next((p for p in (out, *out.parents) if p.exists() and not p.is_dir()), None)
        reason = (f"{blocker} is a file, not a folder" if blocker is not None
                  else err.strerror or str(err))
        raise ValueError(f"cannot write the output folder {out}: {reason}; choose another "
                         f"--out") from None
    return out


def parse_time_steps(text: str | None) -> list[float] | None:
    """``"1/15,1/30,1/60"`` (fractions or decimals, seconds) -> ``[0.0667, 0.0333, 0.0167]``."""
    if not text:
        return None
    try:
        return [float(Fraction(item.strip())) for item in text.split(",")]
    except (ValueError, ZeroDivisionError):
        raise ValueError(f"--continuation expects time steps in seconds separated by commas, "
                         f"coarse to fine, e.g. 1/15,1/30,1/60; got {text!r}") from None


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


def format_value(value) -> str:
    """A default as typed on the command line: ``1/60`` rather than 0.016666666666666666."""
    if isinstance(value, float) and len(repr(value)) > 8:
        fraction = Fraction(value).limit_denominator(1000)
        if float(fraction) == value:
            return str(fraction)
    return str(value)


def cmd_solve(args) -> int:
    from .export import check_library

    for fmt in args.export or ():
        check_library(fmt)  # before the solve, not after it
    module = load_module(args.problem)
    overrides = check_overrides(module, parse_overrides(args.set))  # as build gets them
    continuation = parse_time_steps(args.continuation)
    out = ensure_writable(args.out) if args.out else None
    prob = build_problem(module, **overrides)
    defaults = solve_defaults(module)
    method = args.method or defaults["method"]
    gradient = args.gradient or defaults["gradient"]
    maxiter = args.maxiter if args.maxiter is not None else defaults["maxiter"]
    out = out or ensure_writable(Path("results") / prob.name)
    rounds = {key: value for key, value in (("rounds", args.rounds),
                                             ("weight_growth", args.weight_growth))
              if value is not None} or {k: defaults[k] for k in ("rounds", "weight_growth")
                                        if k in defaults}
    return run_solve(SolveRun(
        prob, out, problem_file=str(resolve(args.problem).resolve()), problem_arg=args.problem,
        overrides=overrides, method=method, gradient=gradient, maxiter=maxiter,
        continuation=continuation, rounds=rounds,
        time_limit=args.time_limit, resume=args.resume, quiet=args.quiet,
        animation=not args.no_animation, exports=tuple(args.export or ()),
        viewer=not args.no_viewer))


def cmd_render(args) -> int:
    return run_render(args.results, animation=not args.no_animation)


def cmd_export(args) -> int:
    return run_export(args.results, args.format, out=args.out)


def cmd_gradcheck(args) -> int:
    from .adjoints import FiniteDifference, get_gradient
    from .studies import relative_error_and_cosine

    prob = load_problem(args.problem, **parse_overrides(args.set))
    rng = np.random.default_rng(args.seed)
    u = args.scale * rng.standard_normal(prob.size)
    names = [n.strip() for n in args.routes.split(",")]
    unknown = [n for n in names if n not in GRADIENT_ROUTES]
    if unknown:
        raise ValueError(f"--routes: unknown gradient route(s) {unknown}; choose from "
                         f"{', '.join(GRADIENT_ROUTES)}")
    routes = {}
    for name in names:
        t = time.perf_counter()
        _, g = get_gradient(name)(prob, u)
        routes[name] = (g, time.perf_counter() - t)
    ref_name = names[-1]
    ref = routes[ref_name][0]
    print(f"{prob.name}: {prob.size} controls; reference route '{ref_name}'")
    for name, (g, sec) in routes.items():
        rel, cos = relative_error_and_cosine(g, ref)
        print(f"  {name:8s} {sec:8.3f} s   relative error {rel:.3e}   cosine {cos:.12f}")
    fd = FiniteDifference(args.h)
    for k in range(args.directions):
        d = rng.standard_normal(prob.size)
        d /= np.linalg.norm(d)
        slope = fd.directional(prob, u, d)
        tangent = prob.directional_derivative(u, d)
        print(f"  direction {k}: central difference {slope:+.10e}  tangent {tangent:+.10e}  "
              + "  ".join(f"{n} {g @ d:+.10e}" for n, (g, _) in routes.items()))
    return 0


def cmd_study(args) -> int:
    from . import studies

    if args.study == "gradient-accuracy":
        print(studies.format_gradient_accuracy(studies.gradient_accuracy(quick=args.quick)))
    else:
        print(studies.format_one_step_gap(studies.one_step_gap(quick=args.quick)))
    return 0


def _output_options(s) -> None:
    """``solve``'s options for what it writes."""
    s.add_argument("--out", help="output folder (default results/PROBLEM)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--no-animation", action="store_true", help="skip the GIF")
    s.add_argument("--no-viewer", action="store_true",
                   help="skip viewer.html, the interactive viewer (needs plotly)")
    s.add_argument("--export", action="append", metavar="FORMAT", choices=EXPORT_FORMATS,
                   help="also export the result: usd, pc2, obj or html (repeatable; see "
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
                        "casadi_keyframe[viewer]); repeatable")
    e.add_argument("--out", help="output folder (default: the results folder)")
    e.set_defaults(func=cmd_export)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="casadi-keyframe", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the problem files").set_defaults(func=cmd_list)
    sh = sub.add_parser("show", help="a problem's description, overrides (type, default, range) "
                                     "and solve defaults")
    sh.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    sh.set_defaults(func=cmd_show)

    s = sub.add_parser("solve", help="optimise a problem and write results and pictures",
                       epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    s.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a build() argument")
    s.add_argument("--method", choices=("lbfgsb", "ipopt"))
    s.add_argument("--gradient", choices=GRADIENT_ROUTES,
                   help="gradient route (default: the problem's SOLVE, else 'adjoint'): "
                        "'adjoint' the exact hand adjoint, 'swapped' the paper's approximate "
                        "one (cloth), 'casadi' CasADi reverse mode (small systems), 'fd' "
                        "finite differences ('exact' is a deprecated name of 'casadi')")
    s.add_argument("--maxiter", type=positive_int, help="iteration limit (per stage with --continuation)")
    s.add_argument("--continuation", metavar="DT,DT,...",
                   help="solve at these time steps first, coarse to fine (e.g. 1/15,1/30,1/60); "
                        "the problem's dt ends the list")
    s.add_argument("--rounds", type=int, metavar="N",
                   help="augmented-Lagrangian rounds: after each, the keyframes aim past their "
                        "target by the miss left (hard keyframes; --maxiter per round)")
    s.add_argument("--weight-growth", type=float, metavar="G",
                   help="multiply the keyframe weights by G per round (a penalty schedule)")
    _output_options(s)
    s.add_argument("--time-limit", type=at_least(float, 0, strict=True), metavar="SECONDS",
                   help="stop the search after this wall time (over all stages and rounds); "
                        "the best result is written, exit code 3")
    s.add_argument("--resume", metavar="DIR_OR_NPZ",
                   help="start from a run's controls: a results folder (the newer of its "
                        "checkpoint.npz and result.npz) or either file; same problem and --set")
    s.set_defaults(func=cmd_solve)

    r = sub.add_parser("render", help="draw a saved run's pictures again (convergence.png, "
                                      "keyframes.png, animation.gif) without solving")
    r.add_argument("results", help="results folder (result.npz and summary.json, or only "
                                    "checkpoint.npz), or one of those .npz files")
    r.add_argument("--no-animation", action="store_true", help="skip the GIF")
    r.set_defaults(func=cmd_render)

    _export_parser(sub)
    g = sub.add_parser("gradcheck", help="compare the gradient routes on a problem")
    g.add_argument("problem")
    g.add_argument("--set", action="append", metavar="KEY=VALUE")
    g.add_argument("--routes", default="adjoint,casadi",
                   help="comma-separated gradient routes; the last is the reference")
    g.add_argument("--directions", type=at_least(int, 0), default=3, help="random central-difference checks")
    g.add_argument("--h", type=at_least(float, 0, strict=True), default=1e-6, help="finite-difference step")
    g.add_argument("--scale", type=at_least(float, 0), default=0.5, help="size of the random controls")
    g.add_argument("--seed", type=int, default=0)
    g.set_defaults(func=cmd_gradcheck)

    st = sub.add_parser("study", help="print an accuracy study (the notebooks' tables)")
    st.add_argument("study", choices=("gradient-accuracy", "integrator-accuracy"))
    st.add_argument("--quick", action="store_true", help="small sizes (as CASADI_KEYFRAME_QUICK=1)")
    st.set_defaults(func=cmd_study)
    return p


def main(argv=None) -> int:
    """Run a command: 0 on success, 1 when the simulation fails, 2 on bad input (a message,
    never a traceback)."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except OverrideError as err:
        print(f"error: {err}\n  'casadi-keyframe show {err.problem}' lists the overrides with "
              f"their types, defaults and ranges", file=sys.stderr)
        return 2
    except SimulationError as err:
        text = " ".join(str(err).split())
        text = text if "simulation" in text else f"the simulation failed: {text}"
        fix = "" if "reduce" in text else "; reduce dt (--set dt=...) or the forces"
        print(f"error: {text}{fix}", file=sys.stderr)
        return 1
    except (ValueError, TypeError, FileNotFoundError, ImportError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
