"""The search in positions with its step solved directly (CHOLMOD on the formed matrix) or
iteratively (conjugate gradients on the operator, the per-frame block preconditioner by
default: ``positions/linear_solve.py``): per iteration the effort, the violation, the damping, the
conjugate gradient iterations and the CPU seconds; at the end the misses, stretch, effort
(rms and peak control acceleration), the replay's distance from the plan, CPU seconds and the
process's peak memory.

    .venv/bin/python benchmarks/transcription_linear.py CASE [--linear iterative]
        [--maxiter 40] [--preconditioner frames|steps|jacobi|none] [--cpu-limit 600]
    .venv/bin/python benchmarks/transcription_linear.py CASE --solves [--after 2]
        [--preconditioner frames,steps,jacobi,none]

CASE: ``mesh12`` (``mesh_keyframes`` 12 x 12), ``walkthrough`` (the README's 30 x 30 sheet,
``benchmarks/search.py``'s overrides), ``walkthroughK`` (its wave and fold on a K x K sheet),
``cape`` (``cape_blend``); every case from the rest
state held still, ``guess=none``, ``rest_band=0.05`` on the sheets.  ``--solves`` times one
iterate's system (the gradient and the keyframes' columns) at several dampings, the direct
factorisation against each preconditioner.  One BLAS thread; CPU time from
``time.process_time``.
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import casadi_keyframe as ck  # noqa: E402
from casadi_keyframe.optimize.finish.constraint import control_hessian  # noqa: E402
from casadi_keyframe.optimize.positions.goal import goal_constraints  # noqa: E402
from casadi_keyframe.optimize.positions.linear_solve import (LinearChoice,  # noqa: E402
                                                             iterative_system)
from casadi_keyframe.optimize.positions.method import start_positions  # noqa: E402
from casadi_keyframe.optimize.positions.replay import replay_controls  # noqa: E402
from casadi_keyframe.optimize.positions.sqp import PositionSQP  # noqa: E402
from casadi_keyframe.optimize.positions.transcription import Transcription  # noqa: E402
from casadi_keyframe.scenes.mesh_targets import write_sheet_and_targets  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from search import walkthrough  # noqa: E402


def load(case: str):
    if case == "mesh12":
        return ck.load_problem("mesh_keyframes", guess="none", rest_band=0.05)
    if case == "walkthrough":
        folder = Path(tempfile.gettempdir()) / "casadi_keyframe_walkthrough"
        return ck.load_problem("mesh_keyframes", **walkthrough(folder), guess="none",
                               rest_band=0.05)
    if case.startswith("walkthrough"):  # walkthroughK: the same wave and fold on K x K
        rows = int(case[len("walkthrough"):])
        folder = Path(tempfile.gettempdir()) / f"casadi_keyframe_walkthrough{rows}"
        if not (folder / "sheet.obj").is_file():
            write_sheet_and_targets(folder, rows, rows)
        return ck.load_problem("mesh_keyframes", cloth=str(folder / "sheet.obj"),
                               pins=(0, rows - 1), guess="none", rest_band=0.05,
                               keyframes=f"40:{folder / 'wave.obj'},80:{folder / 'fold.obj'}")
    if case == "cape":
        return ck.load_problem("cape_blend")
    raise SystemExit(f"unknown case {case!r}: mesh12, walkthrough or cape")


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def search(prob, args):
    tr = Transcription(prob)
    solver = PositionSQP(tr, goal_constraints(tr), control_hessian(prob),
                         LinearChoice(args.linear, preconditioner=args.preconditioner))
    z0 = tr.unknowns(start_positions(prob, "rest", None))
    print(f"{prob.name}: {tr.size} unknowns, linear={args.linear}"
          f" ({'iterative' if solver.linear.iterative(tr.size, tr.nf) else 'direct'})", flush=True)
    print("| it | effort | violation | misses mm | mu | kept | CG iterations | CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    t0 = time.process_time()
    last = [t0]

    def each(report, point):
        now = time.process_time()
        cg = "-" if solver.solves is None else "+".join(map(str, solver.solves.iterations))
        misses = "/".join(f"{1e3 * m:.1f}" for m in report.misses)
        print(f"| {report.iteration} | {report.effort:.4g} | {report.violation:.2e} | "
              f"{misses} | {report.mu:.1e} | {'yes' if report.kept else 'no'} | {cg} | "
              f"{now - last[0]:.1f} |", flush=True)
        last[0] = now

    stop = (lambda: time.process_time() - t0 > args.cpu_limit)
    outcome, x = solver.run(z0, maxiter=args.maxiter, tol=1e-3, on_iteration=each,
                            should_stop=stop)
    seconds = time.process_time() - t0
    replay = replay_controls(prob, tr.frames(outcome.z))
    b = prob.breakdown(replay.u)
    misses = "/".join(f"{1e3 * m['rms_position_error']:.1f}" for m in b["misses"])
    e = b["effort"]
    print(f"\n{outcome.reason} after {outcome.iterations} iterations, {seconds:.0f} s CPU: "
          f"misses {misses} mm, stretch {b['physical']['max_stretch']:.3f}, effort rms "
          f"{e['rms_acceleration']:.1f} / peak {e['peak_acceleration']:.0f} m/s^2, replay "
          f"within {1e3 * replay.deviation:.1e} mm (frame {replay.frame}), peak memory "
          f"{peak_mb():.0f} MB", flush=True)


def solves(prob, args):
    """The system of the direct search's iteration ``--after`` (from rest; 1: the rest state
    itself) at several dampings: each preconditioner's conjugate gradient iterations (to
    the residual ``CG_TOL`` or the model's settling), seconds, and the share of the exact
    step's model decrease its step achieves, against the direct factorisation."""
    tr = Transcription(prob)
    solver = PositionSQP(tr, goal_constraints(tr), control_hessian(prob),
                         LinearChoice("direct"))
    seen, system_of = [], solver._system
    solver._system = lambda x, lam, mu: seen.append((x, np.array(lam))) or system_of(x, lam, mu)
    solver.run(tr.unknowns(start_positions(prob, "rest", None)), maxiter=args.after, tol=0.0)
    solver._system = system_of
    x, lam = seen[-1]
    rhs = np.column_stack([x.gradient, solver._gradients(x.z)])
    print(f"{prob.name}: {tr.size} unknowns, iteration {args.after}'s point, {rhs.shape[1]} "
          "right-hand sides")
    print("| mu | solve | setup s | CG iterations | solve s | relative residual | model |")
    print("|---|---|---|---|---|---|---|")
    for mu in (1e3, 1.0, 1e-2):
        t = time.process_time()
        solve, _, _ = system_of(x, lam, mu)
        t1 = time.process_time()
        exact = solve(rhs)
        print(f"| {mu:g} | direct | {t1 - t:.2f} | - | {time.process_time() - t1:.2f} "
              "| - | 1 |", flush=True)
        for pre in args.preconditioner.split(","):
            choice = LinearChoice("iterative", preconditioner=pre)
            t = time.process_time()
            system = iterative_system(solver, x, lam, mu, choice)
            t1 = time.process_time()
            X = system.solve(rhs)
            t2 = time.process_time()
            B, g = system.operator, rhs[:, 0]
            res = np.linalg.norm(B(X) - rhs, axis=0) / np.linalg.norm(rhs, axis=0)
            model = [float(g @ p - 0.5 * p @ B(p)) for p in (X[:, 0], exact[:, 0])]
            print(f"| {mu:g} | {pre} | {t1 - t:.2f} | {system.solves.iterations[0]} | "
                  f"{t2 - t1:.2f} | {res.max():.1e} | {model[0] / model[1]:.4f} |", flush=True)
    print(f"\npeak memory {peak_mb():.0f} MB")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("case")
    p.add_argument("--linear", default="iterative", choices=("auto", "direct", "iterative"))
    p.add_argument("--preconditioner", default="frames")
    p.add_argument("--maxiter", type=int, default=40)
    p.add_argument("--cpu-limit", type=float, default=600.0)
    p.add_argument("--solves", action="store_true", help="one iterate's solves only")
    p.add_argument("--after", type=int, default=2,
                   help="with --solves: the direct search's iteration whose system is solved")
    args = p.parse_args()
    prob = load(args.case)
    (solves if args.solves else search)(prob, args)


if __name__ == "__main__":
    main()
