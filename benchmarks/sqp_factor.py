"""The search in positions' factorisation in two orderings: CHOLMOD's fill-reducing one and
the unknowns' own (frame after frame), on the step's matrix at the rest start: analysis and
factorisation CPU seconds (one BLAS thread) and the factor's non-zeros, per sheet.

    .venv/bin/python benchmarks/sqp_factor.py [--sizes 8,12,16]

Sheets: ``cloth_shapes`` at half its horizon (``steps=60``) at each size; 12 is the mesh
walkthrough's 12 x 12 sheet (``mesh_keyframes``, 80 steps).
"""
import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from cvxopt import cholmod  # noqa: E402

import casadi_keyframe as ck  # noqa: E402
from casadi_keyframe.optimize.finish.constraint import control_hessian  # noqa: E402
from casadi_keyframe.optimize.positions.goal import goal_constraints  # noqa: E402
from casadi_keyframe.optimize.positions.method import start_positions  # noqa: E402
from casadi_keyframe.optimize.positions.sqp import Factor, PositionSQP  # noqa: E402
from casadi_keyframe.optimize.positions.transcription import Transcription  # noqa: E402


def problem(size: int):
    if size == 12:
        return "mesh_keyframes 12 x 12", ck.load_problem("mesh_keyframes", guess="none",
                                                         rest_band=0.05)
    return f"cloth_shapes {size} x {size}", ck.load_problem("cloth_shapes", rows=size,
                                                            cols=size, steps=60)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="8,12,16")
    args = p.parse_args()
    print("| sheet | unknowns | ordering | analysis s | factorisation s | factor non-zeros |")
    print("|---|---|---|---|---|---|")
    for size in (int(s) for s in args.sizes.split(",")):
        name, prob = problem(size)
        tr = Transcription(prob)
        sqp = PositionSQP(tr, goal_constraints(tr), control_hessian(prob))
        x = sqp.point(tr.unknowns(start_positions(prob, "rest", None)))
        B = x.J.T @ (sqp.Q @ x.J) + sqp._pattern(x) + 100.0 * sqp.metric
        for label, natural in (("CHOLMOD's", False), ("frame after frame", True)):
            factor = Factor(natural=natural)
            t = time.process_time()
            factor(B)  # the first call analyses and factors
            first = time.process_time() - t
            t = time.process_time()
            factor(B)  # the analysis kept: a numeric factorisation only
            numeric = time.process_time() - t
            nnz = len(cholmod.getfactor(factor._symbolic).V)
            print(f"| {name} | {tr.size} | {label} | {first - numeric:.2f} | {numeric:.2f} | "
                  f"{nnz / 1e6:.1f} M |", flush=True)
        del sqp, x, B


if __name__ == "__main__":
    main()
