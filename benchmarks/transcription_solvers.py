"""The search in positions by its solvers, side by side per size: the trust-region SQP
(``solver=sqp``, the default), IPOPT on the effort's Gauss-Newton matrix (``solver=ipopt``)
and IPOPT on its exact Hessian (``hessian=exact``), each from the rest state held still, on the fig. 4 sheet (``cloth_shapes``) at growing sizes and the mesh walkthrough's
12 x 12 sheet.  Per run: keyframe misses, stretch, effort (rms and peak control acceleration
per particle), iterations, CPU seconds, the process's peak memory and the outcome.

    .venv/bin/python benchmarks/transcription_solvers.py [--maxiter 100] [--sizes 4,6,8]
        [--walkthrough]

Each run is a child process (its own peak memory), one BLAS thread, CPU time from
``time.process_time``.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

SOLVERS = {"sqp": {"solver": "sqp"}, "ipopt": {"solver": "ipopt"},
           "ipopt, exact Hessian": {"solver": "ipopt", "hessian": "exact"}}


def one(problem: str, overrides: dict, options: dict, maxiter: int) -> dict:
    """Solve one case in this process; its figures."""
    import casadi_keyframe as ck

    prob = ck.load_problem(problem, **overrides)
    t = time.process_time()
    result = ck.solve(prob, method="transcription", maxiter=maxiter, quiet=True,
                      options={"start": "rest", **options})
    seconds = time.process_time() - t
    b = prob.breakdown(result.x)
    return {"misses": [1e3 * m["rms_position_error"] for m in b["misses"]],
            "stretch": b["physical"]["max_stretch"], "rms": b["effort"]["rms_acceleration"],
            "peak": b["effort"]["peak_acceleration"], "nit": result.nit, "cpu": seconds,
            "memory": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "status": result.status, "message": result.message}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--maxiter", type=int, default=100)
    p.add_argument("--sizes", default="4,6,8", help="cloth_shapes sheet sizes (rows = cols)")
    p.add_argument("--steps", type=int, default=60, help="cloth_shapes' steps")
    p.add_argument("--walkthrough", action="store_true",
                   help="also the mesh walkthrough's 12 x 12 sheet (guess=none, 80 steps)")
    p.add_argument("--case", help=argparse.SUPPRESS)  # a child's case, as JSON
    args = p.parse_args()
    if args.case:
        print(json.dumps(one(**json.loads(args.case))))
        return
    cases = [(f"cloth_shapes {k} x {k}", "cloth_shapes",
              {"rows": int(k), "cols": int(k), "steps": args.steps})
             for k in args.sizes.split(",") if k]
    if args.walkthrough:
        cases.append(("mesh_keyframes 12 x 12", "mesh_keyframes",
                      {"guess": "none", "rest_band": 0.05}))
    print("| sheet | solver | misses mm | stretch | rms / peak m/s^2 | iterations | CPU s | "
          "peak MB | exit | outcome |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for label, problem, overrides in cases:
        for solver, options in SOLVERS.items():
            case = json.dumps({"problem": problem, "overrides": overrides,
                               "options": options, "maxiter": args.maxiter})
            done = subprocess.run([sys.executable, __file__, "--case", case],
                                  capture_output=True, text=True)
            if done.returncode:
                print(f"| {label} | {solver} | failed: {done.stderr.strip()[-300:]} |")
                continue
            r = json.loads(done.stdout.strip().splitlines()[-1])
            misses = "/".join(f"{m:.1f}" for m in r["misses"])
            print(f"| {label} | {solver} | {misses} | {r['stretch']:.3f} | {r['rms']:.1f} / "
                  f"{r['peak']:.0f} | {r['nit']} | {r['cpu']:.0f} | {r['memory']:.0f} | "
                  f"{r['status']} | {r['message'][:160]} |", flush=True)


if __name__ == "__main__":
    main()
