"""The command line's arguments: one parser per command, their help and exit codes."""
from __future__ import annotations

import argparse

from ..adjoints import ROUTES as GRADIENT_ROUTES
from ..adjoints import route_help
from ..export import FORMATS as EXPORT_FORMATS
from ..export import format_help
from ..optimize import METHODS
from ..runs import EXIT_CODES
from ..sweep.plan import SWEEP_EXIT_CODES
from .commands import (cmd_export, cmd_gradcheck, cmd_list, cmd_render, cmd_show, cmd_solve,
                       cmd_study, cmd_sweep)
from .values import at_least, positive_int

def _addrunner_options(p) -> None:
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


def add_sweep_parser(sub) -> None:
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
    add_option_option(w)
    w.add_argument("--gradient", choices=GRADIENT_ROUTES, help=route_help())
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
    _addrunner_options(w)
    w.set_defaults(func=cmd_sweep)


def output_options(s) -> None:
    """``solve``'s options for what it writes."""
    s.add_argument("--out", help="output folder (default results/PROBLEM)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--no-animation", action="store_true", help="skip the GIF")
    s.add_argument("--no-viewer", action="store_true",
                   help="skip viewer.html, the interactive viewer (needs plotly)")
    s.add_argument("--export", action="append", metavar="FORMAT", choices=EXPORT_FORMATS,
                   help=f"also export the result: {', '.join(EXPORT_FORMATS)} (repeatable; see "
                        "'casadi-keyframe export')")


def export_parser(sub) -> None:
    """The ``export`` command."""
    e = sub.add_parser("export", help="write a saved result as USD, a PC2 point cache, an OBJ "
                                      "sequence or the HTML viewer")
    e.add_argument("results", help="results folder (with result.npz), or the result.npz")
    e.add_argument("--format", action="append", required=True, choices=EXPORT_FORMATS,
                   help=format_help() + "; repeatable")
    e.add_argument("--out", help="output folder (default: the results folder)")
    e.set_defaults(func=cmd_export)


def solve_parser(sub) -> None:
    """The ``solve`` command's arguments."""
    s = sub.add_parser("solve", help="optimise a problem and write results and pictures",
                       epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    s.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a build() argument")
    s.add_argument("--method", choices=list(METHODS))
    add_option_option(s)
    s.add_argument("--gradient", choices=GRADIENT_ROUTES, help=route_help())
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
    s.add_argument("--finish", metavar="KIND[,window=N,maxiter=N]",
                   help="a last stage with the keyframes held as a constraint, on the controls "
                        "of the N steps (window, default 12) just before the last keyframe: "
                        "'land' puts keyframes still missed within their tolerances, 'effort' "
                        "then lowers the control cost keeping them there, at most maxiter "
                        "steps each (default 10; state keyframes and per-step forces only); "
                        "'none' drops the problem file's")
    output_options(s)
    s.add_argument("--time-limit", type=at_least(float, 0, strict=True), metavar="SECONDS",
                   help="stop the run after this wall time, counted from its start (the "
                        "problem's build, every stage, round and the finish; pictures "
                        "apart, see --draw-limit); the best result is written, exit code 3")
    s.add_argument("--draw-limit", type=at_least(float, 0, strict=True), metavar="SECONDS",
                   help="the time the animation may take to draw (default 60): beyond it, "
                        "fewer frames are drawn (every keyframe kept) and the run says so")
    s.add_argument("--resume", metavar="DIR_OR_NPZ",
                   help="start from a run's controls: a results folder (the newer of its "
                        "checkpoint.npz and result.npz) or either file; same problem and --set")
    s.add_argument("--from-frame", type=at_least(int, 0), metavar="K",
                   help="with --resume RUN: keep RUN's motion up to frame K exactly (its "
                        "controls before K held, its state at K the start) and solve only "
                        "frames K+1.., against the problem as it is now (changed keyframes, "
                        "colliders: other --set values are fine), warm-started from RUN's "
                        "controls after K (or, where they miss and it stands better, the "
                        "problem's own start on those frames); the result is the whole "
                        "shot, judged whole.  RUN is its folder's "
                        "result.npz; K from the first keyframe to before the last; the cloth, "
                        "dt, the controls and the pins cannot change")
    s.set_defaults(func=cmd_solve)


def gradcheck_parser(sub) -> None:
    """The ``gradcheck`` command's arguments."""
    g = sub.add_parser("gradcheck", help="a gradient route's health at a point: backward "
                                          "growth, dot-product test, central differences, "
                                          "linearity radius, and a verdict")
    g.add_argument("problem")
    g.add_argument("--set", action="append", metavar="KEY=VALUE")
    g.add_argument("--gradient", choices=GRADIENT_ROUTES,
                   help=route_help("the route checked") + "; an approximate one is compared "
                        "with the exact adjoint")
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


def study_parser(sub) -> None:
    """The ``study`` command's arguments (and its grid on the sweep runner)."""
    st = sub.add_parser("study", help="print a study (the notebooks' tables: accuracy, "
                                      "formulations), or run a grid of it as a sweep (--grid)",
                        epilog=SWEEP_EXIT_CODES + "\n\nexample: casadi-keyframe study "
                        "gradient-accuracy --grid dt=1/30,1/60,1/120 --grid stretch=50,500",
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    st.add_argument("study", choices=("gradient-accuracy", "integrator-accuracy",
                                      "swap-validity", "formulations"))
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
    st.add_argument("--out", help="output folder (default results/study-STUDY; formulations: "
                                  "where each run's folder is kept)")
    _addrunner_options(st)
    st.set_defaults(func=cmd_study)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="casadi-keyframe", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the problem files").set_defaults(func=cmd_list)
    sh = sub.add_parser("show", help="a problem's description, overrides (type, default, range) "
                                     "and solve defaults")
    sh.add_argument("problem", help="problem name (see 'list') or path to a problem file")
    sh.set_defaults(func=cmd_show)

    solve_parser(sub)

    r = sub.add_parser("render", help="draw a saved run's pictures again (convergence.png, "
                                      "keyframes.png, animation.gif) without solving")
    r.add_argument("results", help="results folder (result.npz and summary.json, or only "
                                    "checkpoint.npz), or one of those .npz files")
    r.add_argument("--no-animation", action="store_true", help="skip the GIF")
    r.add_argument("--draw-limit", type=at_least(float, 0, strict=True), metavar="SECONDS",
                   help="the time the animation may take to draw (default 60): beyond it, "
                        "fewer frames are drawn (every keyframe kept)")
    r.set_defaults(func=cmd_render)

    export_parser(sub)
    gradcheck_parser(sub)
    study_parser(sub)
    add_sweep_parser(sub)
    debug = "print the whole traceback with an error (the library's own lines included)"
    p.add_argument("--debug", action="store_true", help=debug)
    for command in sub.choices.values():  # also after the command, where users type it
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help=debug)
    return p


def add_option_option(s) -> None:
    """``--option KEY=VALUE``: any option the method documents, checked before the build."""
    s.add_argument("--option", action="append", metavar="KEY=VALUE",
                   help="an option of the method, by the name it documents (repeatable), "
                        "e.g. --option radius=0.5 for gauss-newton, --option maxcor=40 for "
                        "lbfgsb, --option mu_strategy=adaptive for ipopt; checked against "
                        "the method's options before anything is built")


def add_shooting_options(s, whole) -> None:
    """``--segments``, ``--shooting``, ``--scheduler`` and ``--homotopy`` on the parser
    ``s`` (``whole``: the argparse type of a whole number >= 1)."""
    s.add_argument("--segments", type=whole, metavar="K",
                   help="multiple shooting with K segments: the controls and the states where "
                        "segments meet searched together, the segments' defects held by "
                        "multipliers (1: single shooting, not the problem file's default)")
    s.add_argument("--shooting", action="append", metavar="KEY=VALUE,...",
                   help="multiple shooting's options: init=passive|guess|target|blend (where "
                        "the node states start), workers=N (processes sweeping the segments, "
                        "default 1), rounds=N, formulation=lagrangian|ipopt (the defects as "
                        "IPOPT's constraints), penalty=X, growth=X, polish=True|False, "
                        "place=equal|growth (segments of equal length or of equal backward "
                        "growth)")
    s.add_argument("--scheduler", metavar="ADDRESS",
                   help="sweep the segments on the running Dask cluster at ADDRESS (e.g. "
                        "tcp://10.0.0.5:8786) instead of local processes")
    s.add_argument("--homotopy", action="append", metavar="KEY=VALUE,...",
                   help="solve first with the model changed by these build overrides, e.g. "
                        "contact=3 (a cape's contact three times softer and thicker); repeat, "
                        "first to last; the problem's own model ends each mesh")
