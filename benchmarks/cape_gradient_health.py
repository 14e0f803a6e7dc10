"""The gradient routes' health on the cape blend from rest, for each way the cape touches the
body: the problem file has no ``collision`` override, so its model is built here with
``collision=`` guarded (the default), penalty (the paper's springs alone) or constraint.

Prints, per contact model, the swapped and the exact route's backward growth, the swapped
route's cosine and relative error against the exact adjoint, and whether the guard refuses
it (issue 25: 1e53 before the guard), with ``health_report``'s verdict.

    .venv/bin/python benchmarks/cape_gradient_health.py [--rows 6] [--cols 4]
        [--collisions guarded penalty constraint] [--full]   # --full: the whole report
"""
import argparse
import functools
import warnings

from casadi_keyframe.health import GradientRouteWarning
from casadi_keyframe.studies.health_report import format_health, gradient_health
from casadi_keyframe.loading import load_module
from casadi_keyframe.models import COLLISIONS
from casadi_keyframe.scenes import capes


def cape_problem(rows: int, cols: int, collision: str):
    """cape_blend from rest (guess=passive) with the body touched as ``collision`` says."""
    module = load_module("cape_blend")
    module.cape_model = functools.partial(capes.cape_model, collision=collision)
    return module.build(rows=rows, cols=cols, guess="passive")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=6)
    ap.add_argument("--cols", type=int, default=4)
    ap.add_argument("--collisions", nargs="+", default=list(COLLISIONS), choices=COLLISIONS)
    ap.add_argument("--full", action="store_true", help="the whole report (differences, radius)")
    args = ap.parse_args()
    warnings.simplefilter("ignore", GradientRouteWarning)
    print(f"cape_blend {args.rows} x {args.cols}, guess=passive (zero forces)")
    print(f"{'collision':>10} {'growth swapped':>15} {'growth exact':>13} {'cosine':>8} "
          f"{'rel. error':>11}  verdict (swapped)")
    for collision in args.collisions:
        prob = cape_problem(args.rows, args.cols, collision)
        report = gradient_health(prob, route="swapped", directions=0, steps=(1e-6,),
                                 radius=args.full)
        rel, cos = report.versus_exact
        print(f"{collision:>10} {report.growth.growth:15.3g} "
              f"{report.exact_growth.growth:13.3g} {cos:8.3f} {rel:11.3g}  {report.verdict}",
              flush=True)
        if args.full:
            print(format_health(report))


if __name__ == "__main__":
    main()
