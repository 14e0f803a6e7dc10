"""Peak memory of a flock's objective and of its adjoint gradient, one fresh process each.

For ``prob.objective(u)`` and ``prob.objective_and_gradient(u)`` on flock_shapes prints

* traced peak: the largest Python-traced allocation (numpy arrays included) during the call,
  measured by ``tracemalloc`` in its own process;
* maxrss: the process's resident-set peak after the call and before it (problem loaded,
  kernels compiled), measured in another process without ``tracemalloc``.

Each figure comes from a new interpreter, so one call cannot inherit another's peak.

    .venv/bin/python benchmarks/flock_memory.py [--agents 5000] [--steps 200]
"""
import argparse
import json
import resource
import subprocess
import sys

CALLS = {"objective": lambda prob, u: prob.objective(u),
         "objective_and_gradient": lambda prob, u: prob.objective_and_gradient(u, "adjoint")}


def measure(call: str, how: str, agents: int, steps: int) -> dict:
    """Load the problem, then run ``call`` once under ``how`` ("traced" or "rss")."""
    import numpy as np

    from casadi_keyframe import load_problem
    from timing import traced_peak_mb

    prob = load_problem("flock_shapes", agents=agents, steps=steps)
    u = 0.1 * np.random.default_rng(0).standard_normal(prob.size)
    fn = CALLS[call]
    if how == "traced":
        return {"traced_mb": traced_peak_mb(lambda: fn(prob, u))}
    before = _maxrss_mb()
    fn(prob, u)
    return {"rss_before_mb": before, "rss_after_mb": _maxrss_mb()}


def _maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kilobytes


def in_fresh_process(call: str, how: str, agents: int, steps: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--one", call, how, "--agents", str(agents),
                          "--steps", str(steps)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=5000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--one", nargs=2, metavar=("CALL", "HOW"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(measure(*args.one, args.agents, args.steps)))
        return
    print(f"flock_shapes, {args.agents} agents x {args.steps} steps")
    print(f"{'call':>24} {'traced peak MB':>15} {'maxrss before MB':>17} {'maxrss after MB':>16}")
    for call in CALLS:
        traced = in_fresh_process(call, "traced", args.agents, args.steps)
        rss = in_fresh_process(call, "rss", args.agents, args.steps)
        print(f"{call:>24} {traced['traced_mb']:15.1f} {rss['rss_before_mb']:17.1f} "
              f"{rss['rss_after_mb']:16.1f}", flush=True)


if __name__ == "__main__":
    main()
