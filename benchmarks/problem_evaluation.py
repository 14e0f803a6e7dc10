"""CPU and wall seconds of one objective and one gradient of full-size problems, at their
start (``initial_controls``) and with their solve defaults' gradient route.

    .venv/bin/python benchmarks/problem_evaluation.py [cloth_toss cape_blend] [--repeat 3]

One row per problem: particles, steps, objective CPU s and wall s, gradient CPU s and wall s
(medians); run it under ``benchmarks/compare_revisions.py`` to compare two checkouts.
"""
import argparse
import statistics
import time

from casadi_keyframe.loading import build_problem, load_module, solve_defaults
from casadi_keyframe.optimize.settings import settings_from


def timed(fn) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    fn()
    return time.process_time() - cpu, time.perf_counter() - wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("problems", nargs="*", default=["cloth_toss", "cape_blend"])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"{'problem':12} {'particles':>9} {'steps':>5} {'obj CPU':>8} {'obj wall':>8} "
          f"{'grad CPU':>8} {'grad wall':>9}")
    for name in args.problems:
        module = load_module(name)
        prob = build_problem(module)
        route = settings_from(solve_defaults(module)).gradient
        u = prob.initial_controls()
        prob.objective_and_gradient(u, route)  # compiles the kernels
        runs = [(timed(lambda: prob.objective(u)),
                 timed(lambda: prob.objective_and_gradient(u, route)))
                for _ in range(args.repeat)]
        med = [statistics.median(r[i][j] for r in runs) for i in (0, 1) for j in (0, 1)]
        print(f"{name:12} {prob.model.n:9d} {prob.steps:5d} {med[0]:8.2f} {med[1]:8.2f} "
              f"{med[2]:8.2f} {med[3]:9.2f}", flush=True)


if __name__ == "__main__":
    main()
