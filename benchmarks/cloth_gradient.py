"""Forward pass versus swapped-adjoint gradient for hanging cloth of 10x10..50x50 particles.

Per size: forward seconds, gradient seconds (forward + the integrator-swapping adjoint), their
ratio (target: at most 2), the peak memory traced during the gradient and the seconds of the
exact hand adjoint's gradient (``gradient="adjoint"``); where the unrolled graph fits, the exact
CasADi gradient too (build + first call, later calls, peak RSS growth) and how far the
swapped gradient is from it (cosine, relative error).

The sheet hangs from its two top corners; by default a sphere of radius 0.2 m starts 2 cm
clear of its contact layer and presses into it at 6 cm/s.  (A sphere already cutting the
sheet at t = 0 blows the 20x20 and 50x50 sheets up.)  The controls are random forces giving
each particle 1 m/s^2 rms acceleration (0.01 N at 10x10): fixed 0.01 N forces blow up the
50x50 sheet, whose particles weigh 0.4 g.  The default solver is the library's, the modified
PCG (the step matrix is positive definite since the stiffness is clamped); ``--solver direct``
uses SuperLU.

    .venv/bin/python benchmarks/cloth_gradient.py [--sizes 10 20 50] [--steps 100] [--repeat 3]
        [--collider sphere|none] [--solver cg|direct] [--exact-max-particles 100]
"""
import argparse
import os
import resource
import sys
import time

import numpy as np

from casadi_keyframe import ControlProblem
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models.colliders import Sphere
from casadi_keyframe.scenes.sheets import hanging_sheet, swing_problem
from casadi_keyframe.studies import relative_error_and_cosine
from timing import best_of, traced_peak_mb

RSS_UNIT = 2 ** 20 if sys.platform == "darwin" else 2 ** 10  # ru_maxrss: bytes or KiB


def sphere_center(t):
    """The sphere's path: 3 cm from the sheet's plane at t = 0, moving into it at 6 cm/s."""
    return np.array([0.5, 0.23 - 0.06 * t, -0.8])


def build(k: int, steps: int, collider: str, solver: str) -> ControlProblem:
    """A k x k hanging sheet (1 m, 1 kg, no ground) swung forward and up."""
    colliders = [Sphere(sphere_center, 0.2)] if collider == "sphere" else []
    return swing_problem(hanging_sheet(k, ground=False, colliders=colliders), steps, 1 / 60,
                         LinearizedBackwardEuler(solver=solver),
                         reach=(0.0, 0.3, 0.1), midway=(0.0, 0.2, 0.0), name=f"cloth{k}")


def random_controls(prob) -> np.ndarray:
    """Per-step forces of 1 m/s^2 rms acceleration on every particle."""
    noise = np.random.default_rng(0).standard_normal((prob.steps, prob.model.n, 3))
    return (noise * prob.model.masses[:, None]).ravel()


def exact_columns(prob, u, g_swapped, repeats: int) -> str:
    """Exact CasADi gradient: build + first call s, later call s, RSS growth MB, cos, rel err."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    _, g = prob.objective_and_gradient(u, "casadi")
    build_s = time.perf_counter() - t
    rss_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss) * RSS_UNIT / 2 ** 20
    call_s = best_of(lambda: prob.objective_and_gradient(u, "casadi"), repeats)
    rel, cos = relative_error_and_cosine(g_swapped, g)
    return f"{build_s:9.2f} {call_s:7.3f} {rss_mb:7.0f} {cos:7.4f} {rel:7.3f}"


def measure(k: int, args) -> tuple[float, str]:
    """One table row for a k x k sheet; returns (gradient / forward, row)."""
    prob = build(k, args.steps, args.collider, args.solver)
    u = random_controls(prob)
    prob.simulate()  # passive run: compiles the kernels; a SimulationError propagates
    _, g_swapped = prob.objective_and_gradient(u, "swapped")
    exact = f"{'-':>9} {'-':>7} {'-':>7} {'-':>7} {'-':>7}"
    if k * k * args.steps <= args.exact_max_particles * 100:
        exact = exact_columns(prob, u, g_swapped, args.repeat)  # first: before RSS grows
    fwd = best_of(lambda: prob.simulate(u), args.repeat)
    grad = best_of(lambda: prob.objective_and_gradient(u, "swapped"), args.repeat)
    peak = traced_peak_mb(lambda: prob.objective_and_gradient(u, "swapped"))
    hand_s = best_of(lambda: prob.objective_and_gradient(u, "adjoint"), args.repeat)
    row = (f"{k:>2d}x{k:<3d} {k * k:9d} {fwd:9.3f} {grad:10.3f} {grad / fwd:6.2f} {peak:8.1f} "
           f"{hand_s:8.3f} " + exact)
    return grad / fwd, row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--collider", choices=["sphere", "none"], default="sphere")
    ap.add_argument("--solver", choices=["direct", "cg"], default="cg")
    ap.add_argument("--exact-max-particles", type=int, default=100,
                    help="exact gradient when particles x steps <= this x 100")
    args = ap.parse_args()
    print(f"Cloth, {args.steps} steps of 1/60 s, collider: {args.collider}, solver: "
          f"{args.solver}; best of {args.repeat} on {os.cpu_count()} cores; gradient = forward "
          "+ swapped adjoint; hand s = gradient with the exact hand adjoint; adjoint MB = tracemalloc peak; exact MB = peak RSS growth "
          "(ru_maxrss; tracemalloc misses CasADi's C++ memory); cos, rel err: swapped vs exact")
    print(f"{'size':6} {'particles':>9} {'forward s':>9} {'gradient s':>10} {'ratio':>6} "
          f"{'adj MB':>8} {'hand s':>8} {'exact 1st':>9} {'exact s':>7} {'ex MB':>7} {'cos':>7} {'rel err':>7}")
    ratios = {}
    for k in sorted(args.sizes):
        ratios[k], row = measure(k, args)
        print(row, flush=True)
    worst = max(ratios, key=ratios.get)
    verdict = "met" if ratios[worst] <= 2 else "MISSED"
    print(f"ratio target (gradient <= 2x forward): {verdict}; worst {ratios[worst]:.2f} at "
          f"{worst}x{worst}")


if __name__ == "__main__":
    main()
