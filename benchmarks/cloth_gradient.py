"""Cloth forward pass and gradients per linear solver, for k x k hanging sheets.

For each size and each solver (``--solvers``, default auto, cholmod, direct, cg: the default
path users get, CHOLMOD, SuperLU and the modified PCG with Jacobi preconditioner), one fresh
subprocess with one BLAS thread builds the problem, runs it once (kernels compiled), then
``--repeat`` rounds of: forward pass (objective only), gradient with the swapped adjoint,
gradient with the exact hand adjoint.  It prints medians of CPU seconds
(``time.process_time``) and wall seconds, the gradients' ratios to the forward pass (CPU),
how much the process's peak RSS grew over the gradients (from after a first forward pass
without records: kernels compiled, nothing kept) and what the forward pass kept of
factorisations for the adjoint (the solver's estimate), then checks the targets: at 50 x 50
forward <= 3.5 s CPU, swapped gradient <= 1.4 x and exact <= 1.6 x forward (on the default
path, "auto": <= 1.35 x and <= 1.5 x); at 100 x 100 the fastest solver >= 3 x faster than
CG in forward and gradients.

The sheet (1 m, 1 kg) hangs from its two top corners; a sphere of radius 0.2 m starts 3 cm
clear of it and presses into it at 6 cm/s; the controls are random forces of 1 m/s^2 rms
acceleration on every particle; 100 steps of 1/60 s.

    .venv/bin/python benchmarks/cloth_gradient.py [--sizes 20 50 100] [--steps 100]
        [--repeat 3] [--solvers auto cholmod direct cg] [--collider sphere|none]
        [--max-factor-gb 2]
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

SINGLE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def sphere_center(t):
    """The sphere's path: 3 cm from the sheet's plane at t = 0, moving into it at 6 cm/s."""
    return np.array([0.5, 0.23 - 0.06 * t, -0.8])


def build(k: int, steps: int, collider: str, solver: str, max_factor_gb: float = 2.0):
    """A k x k hanging sheet (1 m, 1 kg, no ground) swung forward and up."""
    from casadi_keyframe.integrators import LinearizedBackwardEuler
    from casadi_keyframe.models.contact.colliders import Sphere
    from casadi_keyframe.scenes.sheets import hanging_sheet, swing_problem
    colliders = [Sphere(sphere_center, 0.2)] if collider == "sphere" else []
    return swing_problem(hanging_sheet(k, ground=False, colliders=colliders), steps, 1 / 60,
                         LinearizedBackwardEuler(solver=solver,
                                                 max_factor_memory=max_factor_gb * 2 ** 30),
                         reach=(0.0, 0.3, 0.1), midway=(0.0, 0.2, 0.0), name=f"cloth{k}")


def random_controls(prob) -> np.ndarray:
    """Per-step forces of 1 m/s^2 rms acceleration on every particle."""
    noise = np.random.default_rng(0).standard_normal((prob.steps, prob.model.n, 3))
    return (noise * prob.model.masses[:, None]).ravel()


def timed(fn) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    fn()
    return time.process_time() - cpu, time.perf_counter() - wall


def measure(k: int, steps: int, collider: str, solver: str, repeat: int,
            max_factor_gb: float) -> dict:
    """One (size, solver) in this process: medians of CPU and wall seconds per pass."""
    prob = build(k, steps, collider, solver, max_factor_gb)
    u = random_controls(prob)
    prob.simulate(u, records=False)  # compiles the kernels; a SimulationError propagates
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    traj = prob.simulate(u)
    kept = sum(r.factor.nbytes for r in traj.records if r.factor is not None)
    del traj
    passes = {"forward": lambda: prob.simulate(u, records=False),
              "swapped": lambda: prob.objective_and_gradient(u, "swapped"),
              "exact": lambda: prob.objective_and_gradient(u, "adjoint")}
    times = {name: [] for name in passes}
    for _ in range(repeat):
        for name, fn in passes.items():
            times[name].append(timed(fn))
    out = {f"{name}_{kind}": statistics.median(t[i] for t in runs)
           for name, runs in times.items() for i, kind in enumerate(("cpu", "wall"))}
    growth = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0
    out.update(peak_growth_mb=growth * (1 if sys.platform == "darwin" else 1024) / 2 ** 20,
               kept_mb=kept / 2 ** 20)
    return out


def run_child(k: int, solver: str, args) -> dict:
    """:func:`measure` in a fresh interpreter with one BLAS thread (its own peak RSS)."""
    cmd = [sys.executable, __file__, "--child", str(k), solver, "--steps", str(args.steps),
           "--repeat", str(args.repeat), "--collider", args.collider,
           "--max-factor-gb", str(args.max_factor_gb)]
    done = subprocess.run(cmd, env={**os.environ, **SINGLE_THREAD}, capture_output=True,
                          text=True)
    if done.returncode:
        return {"error": (done.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def verdicts(results: dict) -> list[str]:
    lines = []
    for (k, solver), r in results.items():
        if k == 50 and "error" not in r and solver != "cg":
            fwd, sw, ex = r["forward_cpu"], r["swapped_cpu"], r["exact_cpu"]
            swap_max, exact_max = (1.35, 1.5) if solver == "auto" else (1.4, 1.6)
            ok = fwd <= 3.5 and sw <= swap_max * fwd and ex <= exact_max * fwd
            lines.append(f"50x50 {solver}: forward {fwd:.2f} s (<= 3.5), swapped {sw / fwd:.2f}x "
                         f"(<= {swap_max}), exact {ex / fwd:.2f}x (<= {exact_max}): "
                         f"{'met' if ok else 'MISSED'}")
    for k in sorted({k for k, _ in results}):
        cg = results.get((k, "cg"))
        rows = [(s, r) for (kk, s), r in results.items()
                if kk == k and s != "cg" and "error" not in r]
        if not rows or cg is None or "error" in cg:
            continue
        best, r = min(rows, key=lambda row: row[1]["swapped_cpu"])
        speed = {p: cg[f"{p}_cpu"] / r[f"{p}_cpu"] for p in ("forward", "swapped", "exact")}
        text = ", ".join(f"{p} {s:.1f}x" for p, s in speed.items())
        met = " (target >= 3x: " + ("met)" if min(speed.values()) >= 3 else "MISSED)")
        lines.append(f"{k}x{k} {best} vs cg: {text}" + (met if k == 100 else ""))
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[20, 50, 100])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--solvers", nargs="+", default=["auto", "cholmod", "direct", "cg"])
    ap.add_argument("--collider", choices=["sphere", "none"], default="sphere")
    ap.add_argument("--max-factor-gb", type=float, default=2.0,
                    help="the integrator's max_factor_memory in GiB (default: its own, 2)")
    ap.add_argument("--child", nargs=2, metavar=("SIZE", "SOLVER"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        k, solver = int(args.child[0]), args.child[1]
        print(json.dumps(measure(k, args.steps, args.collider, solver, args.repeat,
                                 args.max_factor_gb)))
        return
    print(f"Cloth, {args.steps} steps of 1/60 s, collider: {args.collider}, factors kept up to "
          f"{args.max_factor_gb:g} GiB; median of "
          f"{args.repeat} rounds, one process and one BLAS thread per row; CPU s = "
          "process_time; ratios = gradient CPU / forward CPU; peak MB = growth of peak RSS "
          "over the gradients; kept MB = factorisations the forward pass kept")
    head = (f"{'size':7} {'solver':8} {'fwd CPU':>8} {'fwd wall':>8} {'swap CPU':>8} "
            f"{'ratio':>5} {'exact CPU':>9} {'ratio':>5} {'grad wall':>9} {'peak MB':>7} "
            f"{'kept MB':>7}")
    print(head)
    results = {}
    for k in sorted(args.sizes):
        for solver in args.solvers:
            r = results[k, solver] = run_child(k, solver, args)
            if "error" in r:
                print(f"{k:>3d}x{k:<3d} {solver:8} failed: {r['error']}", flush=True)
                continue
            fwd = r["forward_cpu"]
            print(f"{k:>3d}x{k:<3d} {solver:8} {fwd:8.2f} {r['forward_wall']:8.2f} "
                  f"{r['swapped_cpu']:8.2f} {r['swapped_cpu'] / fwd:5.2f} "
                  f"{r['exact_cpu']:9.2f} {r['exact_cpu'] / fwd:5.2f} "
                  f"{r['swapped_wall']:9.2f} {r['peak_growth_mb']:7.0f} {r['kept_mb']:7.0f}",
                  flush=True)
    for line in verdicts(results):
        print(line)


if __name__ == "__main__":
    main()
