"""The ``casadi-keyframe`` command line: list, solve and gradcheck problems; print studies."""
from __future__ import annotations

import argparse
import ast
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

from .loading import list_problems, load_module, load_problem


def parse_overrides(items) -> dict:
    """``["agents=50", "cutoff=hard"]`` -> ``{"agents": 50, "cutoff": "hard"}``."""
    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.isidentifier():
            raise SystemExit(f"--set expects key=value, got {item!r}")
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[key] = value
    return out


def parse_time_steps(text: str | None) -> list[float] | None:
    """``"1/15,1/30,1/60"`` (fractions or decimals, seconds) -> ``[0.0667, 0.0333, 0.0167]``."""
    if not text:
        return None
    try:
        return [float(Fraction(item.strip())) for item in text.split(",")]
    except (ValueError, ZeroDivisionError):
        raise SystemExit(f"--continuation expects time steps in seconds separated by commas, "
                         f"coarse to fine, e.g. 1/15,1/30,1/60; got {text!r}") from None


def cmd_list(args) -> int:
    for name, doc in list_problems():
        print(f"{name:20s} {doc}")
    return 0


def cmd_solve(args) -> int:
    from . import render
    from .io import save_result
    from .optimize import solve

    overrides = parse_overrides(args.set)
    prob = load_problem(args.problem, **overrides)
    defaults = getattr(load_module(args.problem), "SOLVE", {})
    method = args.method or defaults.get("method", "lbfgsb")
    maxiter = args.maxiter or defaults.get("maxiter", 200)
    out = Path(args.out or Path("results") / prob.name)
    out.mkdir(parents=True, exist_ok=True)
    options = dict(method=method, gradient=args.gradient, maxiter=maxiter, quiet=args.quiet,
                   checkpoint=out / "checkpoint.npz",
                   continuation=parse_time_steps(args.continuation))
    start = prob.breakdown(prob.initial_controls())
    print(f"{prob.name}: {prob.size} controls; start ({'guess' if prob.has_guess else 'passive'}"
          f"): objective {start['objective']:.6g}; {format_misses(start['misses'])}")
    rounds = {key: value for key, value in (("rounds", args.rounds),
                                             ("weight_growth", args.weight_growth))
              if value is not None} or {k: defaults[k] for k in ("rounds", "weight_growth")
                                        if k in defaults}
    if rounds:
        from .augmented_lagrangian import solve_augmented
        result = solve_augmented(prob, **rounds, **options)
    else:
        result = solve(prob, **options)
    summary = save_result(result, out, problem_name=prob.name, overrides=overrides)
    render.convergence(result, out / "convergence.png")
    render.snapshot(prob, result.trajectory, out / "keyframes.png")
    if not args.no_animation:
        render.animate(prob, result.trajectory, out / "animation.gif")
    print(f"{prob.name}: {result.message}")
    print(f"  objective {summary['fun']:.6g}  iterations {result.nit}  evaluations "
          f"{result.nfev}  wall {result.timings['wall_seconds']:.1f} s")
    if len(result.stages) > 1:
        for st in result.stages:
            print("  " + format_stage(st))
    for miss in summary["breakdown"]["misses"]:
        print(f"  {format_misses([miss])}")
    print(f"  written to {out}/")
    return 0


def format_stage(stage: dict) -> str:
    """One line for a continuation stage (its dt) or an augmented-Lagrangian round (its
    weight scale and keyframe misses)."""
    head = (f"round {stage['stage']}: weight x{stage['weight_scale']:.3g}"
            if "weight_scale" in stage else
            f"stage {stage['stage']}: dt {stage['dt']:.6g} s, {stage['steps']} steps")
    line = (f"{head}, {stage['nit']} iterations, objective {stage['fun']:.6g}, "
            f"{stage['seconds']:.1f} s")
    if stage.get("misses"):
        line += "; " + format_misses(stage["misses"])
    return line


def format_misses(misses) -> str:
    """``"StateKeyframe@60 rms_position_error 0.01, ..."``, terms separated by "; "."""
    return "; ".join(f"{m['term']} " + ", ".join(f"{k} {v:.4g}" for k, v in m.items()
                                                 if k != "term") for m in misses)


def cmd_gradcheck(args) -> int:
    from .gradients import FiniteDifference, get_gradient

    prob = load_problem(args.problem, **parse_overrides(args.set))
    rng = np.random.default_rng(args.seed)
    u = args.scale * rng.standard_normal(prob.size)
    routes = {}
    for name in args.routes.split(","):
        t = time.perf_counter()
        _, g = get_gradient(name)(prob, u)
        routes[name] = (g, time.perf_counter() - t)
    ref_name = args.routes.split(",")[-1]
    ref = routes[ref_name][0]
    print(f"{prob.name}: {prob.size} controls; reference route '{ref_name}'")
    for name, (g, sec) in routes.items():
        rel = np.linalg.norm(g - ref) / max(np.linalg.norm(ref), 1e-300)
        cos = g @ ref / max(np.linalg.norm(g) * np.linalg.norm(ref), 1e-300)
        print(f"  {name:8s} {sec:8.3f} s   relative error {rel:.3e}   cosine {cos:.12f}")
    fd = FiniteDifference(args.h)
    for k in range(args.directions):
        d = rng.standard_normal(prob.size)
        d /= np.linalg.norm(d)
        slope = fd.directional(prob, u, d)
        print(f"  direction {k}: central difference {slope:+.10e}  " + "  ".join(
            f"{n} {g @ d:+.10e}" for n, (g, _) in routes.items()))
    return 0


def cmd_study(args) -> int:
    from . import studies

    if args.study == "gradient-accuracy":
        print(studies.format_gradient_accuracy(studies.gradient_accuracy(quick=args.quick)))
    else:
        print(studies.format_one_step_gap(studies.one_step_gap(quick=args.quick)))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="casadi-keyframe", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the problem files").set_defaults(func=cmd_list)

    s = sub.add_parser("solve", help="optimise a problem and write results and pictures")
    s.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    s.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a build() argument")
    s.add_argument("--method", choices=("lbfgsb", "ipopt"))
    s.add_argument("--gradient", default="adjoint", choices=("adjoint", "exact", "fd"))
    s.add_argument("--maxiter", type=int, help="iteration limit (per stage with --continuation)")
    s.add_argument("--continuation", metavar="DT,DT,...",
                   help="solve at these time steps first, coarse to fine (e.g. 1/15,1/30,1/60); "
                        "the problem's dt ends the list")
    s.add_argument("--rounds", type=int, metavar="N",
                   help="augmented-Lagrangian rounds: after each, the keyframes aim past their "
                        "target by the miss left (hard keyframes; --maxiter per round)")
    s.add_argument("--weight-growth", type=float, metavar="G",
                   help="multiply the keyframe weights by G per round (a penalty schedule)")
    s.add_argument("--out", help="output folder (default results/PROBLEM)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--no-animation", action="store_true", help="skip the GIF")
    s.set_defaults(func=cmd_solve)

    g = sub.add_parser("gradcheck", help="compare the gradient routes on a problem")
    g.add_argument("problem")
    g.add_argument("--set", action="append", metavar="KEY=VALUE")
    g.add_argument("--routes", default="adjoint,exact", help="comma-separated; last is the reference")
    g.add_argument("--directions", type=int, default=3, help="random central-difference checks")
    g.add_argument("--h", type=float, default=1e-6, help="finite-difference step")
    g.add_argument("--scale", type=float, default=0.5, help="size of the random controls")
    g.add_argument("--seed", type=int, default=0)
    g.set_defaults(func=cmd_gradcheck)

    st = sub.add_parser("study", help="print an accuracy study (the notebooks' tables)")
    st.add_argument("study", choices=("gradient-accuracy", "integrator-accuracy"))
    st.add_argument("--quick", action="store_true", help="small sizes (as CASADI_KEYFRAME_QUICK=1)")
    st.set_defaults(func=cmd_study)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, TypeError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
