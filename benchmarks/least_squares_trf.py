"""scipy's trust-region reflective ``least_squares`` (LSMR on the matrix-free products,
:class:`~casadi_keyframe.optimize.residual.linearization.Linearization`) against the library's own
trust region (``solve(..., "gauss-newton")``) on one problem, from its start: why the method
is the library's own.  One BLAS thread, CPU time.

    python benchmarks/least_squares_trf.py mesh_keyframes --set guess=none --max-nfev 40

Per run: the objective, each keyframe's rms miss (mm), evaluations (simulations with
records for scipy: every trial point and every Jacobian), Jacobian products and CPU seconds.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from casadi_keyframe.cli.values import parse_overrides  # noqa: E402
from casadi_keyframe.loading import load_problem  # noqa: E402
from casadi_keyframe.optimize import solve  # noqa: E402
from casadi_keyframe.optimize.residual.linearization import linearize  # noqa: E402


class Linearized:
    """The residual function and Jacobian operator scipy asks for, one linearization kept
    (the last point's), counting simulations and products."""

    def __init__(self, problem):
        self.problem, self.lin, self.simulations, self.products = problem, None, 0, 0
        self.u = None

    def at(self, u):
        if self.lin is None or not np.array_equal(self.u, u):
            if self.lin is not None:
                self.products += self.lin.products
                self.lin.release()
            self.lin, self.u = linearize(self.problem, u), u.copy()
            self.simulations += 1
        return self.lin

    def residual(self, u):
        return self.at(np.asarray(u, float)).residual

    def jacobian(self, u, *_):
        return self.at(np.asarray(u, float)).operator()


def misses(problem, u) -> str:
    return ",".join(f"{1e3 * m['rms_position_error']:.1f}"
                    for m in problem.breakdown(u)["misses"] if "rms_position_error" in m)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("problem")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--max-nfev", type=int, default=40)
    parser.add_argument("--lsmr-maxiter", type=int, default=50)
    args = parser.parse_args(argv)
    problem = load_problem(args.problem, **parse_overrides(args.set))
    u0 = problem.initial_controls()
    print(f"start: objective {problem.objective(u0):.5g}, misses {misses(problem, u0)} mm")

    t, lin = time.process_time(), Linearized(problem)
    out = least_squares(lin.residual, u0, jac=lin.jacobian, method="trf", tr_solver="lsmr",
                        x_scale=1.0, tr_options={"maxiter": args.lsmr_maxiter},
                        max_nfev=args.max_nfev)
    products = lin.products + lin.lin.products
    print(f"scipy trf/lsmr: objective {out.cost:.5g}, misses {misses(problem, out.x)} mm, "
          f"{out.nfev} fun + {out.njev} jac calls, {lin.simulations} simulations, "
          f"{products} products, {time.process_time() - t:.1f} s; {out.message}")

    t = time.process_time()
    r = solve(problem, "gauss-newton", quiet=True, stop="method",
              maxiter=args.max_nfev, options={"maxfun": args.max_nfev})
    print(f"gauss-newton: objective {r.fun:.5g}, misses {misses(problem, r.x)} mm, "
          f"{r.nit} iterations, {r.nfev} evaluations, {time.process_time() - t:.1f} s; "
          f"{r.message}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
