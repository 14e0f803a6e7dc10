"""Forward pass versus adjoint gradient for flocks of 100..5000 agents, 200 steps.

Prints forward seconds, gradient seconds (forward + adjoint backward pass), their ratio
(target: at most 2.5) and the peak memory traced during the gradient (target: growing like
agents x steps, not agents^2).  Ratios are measured in one run on one machine.

    .venv/bin/python benchmarks/flock_gradient.py [--agents 100 200 1000 5000] [--steps 200]
"""
import argparse

import numpy as np

from casadi_keyframe import load_problem
from timing import best_of, traced_peak_mb


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[100, 200, 1000, 5000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"{'agents':>7} {'steps':>6} {'pairs/step':>10} {'forward s':>10} {'gradient s':>11} "
          f"{'ratio':>6} {'peak MB':>8} {'bytes/(agent*step)':>19}")
    for n in args.agents:
        prob = load_problem("flock_path", agents=n, steps=args.steps)
        u = 0.1 * np.random.default_rng(0).standard_normal(prob.size)
        traj = prob.simulate(u)  # warm-up (JIT compile happens at load)
        pairs = np.mean([t.i.size for t in traj.records])
        fwd = best_of(lambda: prob.simulate(u), args.repeats)
        grad = best_of(lambda: prob.objective_and_gradient(u, "adjoint"), args.repeats)
        peak = traced_peak_mb(lambda: prob.objective_and_gradient(u, "adjoint")) * 2**20
        print(f"{n:7d} {args.steps:6d} {pairs:10.0f} {fwd:10.3f} {grad:11.3f} {grad / fwd:6.2f} "
              f"{peak / 2**20:8.1f} {peak / (n * args.steps):19.0f}", flush=True)


if __name__ == "__main__":
    main()
