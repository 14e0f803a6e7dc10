"""Every contact law and gradient route against the forward pass itself: the relative error
of each route's derivative along a random direction against the stable central difference
of ``simulate`` (:mod:`casadi_keyframe.studies.forward_differences`: Richardson-refined
central differences, stable within 1e-5 over at least three decades of h), for each scene of
:mod:`casadi_keyframe.scenes.contact_gradients` (held, guarded, penalty, self-contact,
moving and mesh bodies; sliding and sticking) at mu = 0, 0.3, 0.6 and 1.

Routes: ``adjoint`` (the hand adjoint), ``casadi`` (reverse mode through the symbolic step),
``tangent`` (the tangent pass, ``directional_derivative``) and ``swapped`` (the paper's
approximate adjoint, for its size).  ``contacts`` counts the contacts over the steps that
stuck / slid (friction's; a frictionless body has neither).  The penalty springs carry no friction: that scene runs at mu = 0 only.

    .venv/bin/python benchmarks/contact_gradients.py [--laws held mesh] [--mu 0 1]
        [--motions sliding] [--rows 4] [--steps 8] [--routes adjoint casadi tangent swapped]
"""
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from casadi_keyframe.scenes.contact_gradients import (LAWS, MOTIONS,  # noqa: E402
                                                      contact_gradient_problem)
from casadi_keyframe.studies.forward_differences import stable_difference  # noqa: E402

ROUTES = ("adjoint", "casadi", "tangent", "swapped")


def slopes(prob, u, d, routes) -> dict:
    """Each route's derivative along d."""
    out = {}
    for route in routes:
        if route == "tangent":
            out[route] = prob.directional_derivative(u, d)
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out[route] = prob.objective_and_gradient(u, route)[1] @ d
    return out


def contacts(prob, u) -> tuple[int, int]:
    """How many contacts stuck and slid, summed over the steps."""
    held = [r.held for r in prob.simulate(u).records if r.held is not None]
    stuck = sum(int(h.stick.sum()) for h in held if h.frictional)
    slid = sum(int((~h.stick).sum()) for h in held if h.frictional)
    return stuck, slid


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laws", nargs="+", default=list(LAWS), choices=LAWS)
    ap.add_argument("--mu", type=float, nargs="+", default=[0.0, 0.3, 0.6, 1.0])
    ap.add_argument("--motions", nargs="+", default=list(MOTIONS), choices=MOTIONS)
    ap.add_argument("--routes", nargs="+", default=list(ROUTES), choices=ROUTES)
    ap.add_argument("--rows", type=int, default=4)
    ap.add_argument("--steps", type=int, default=8)
    args = ap.parse_args()
    print(f"relative error of each route's derivative along a random direction against the "
          f"stable central difference of simulate; {args.rows} x {args.rows} sheets, "
          f"{args.steps} steps at dt = 1/60")
    print(f"{'law':13s} {'motion':9s} {'mu':>4s} {'contacts':>9s} "
          + "".join(f"{r:>10s}" for r in args.routes) + "   stable window")
    worst = {r: 0.0 for r in args.routes}
    for law in args.laws:
        for motion in args.motions:
            for mu in (args.mu if law != "penalty" else [0.0]):
                t = time.process_time()
                prob, u = contact_gradient_problem(law, mu, motion, rows=args.rows,
                                                   steps=args.steps)
                d = np.random.default_rng(1).standard_normal(prob.size)
                d /= np.linalg.norm(d)
                found = slopes(prob, u, d, args.routes)
                fd = stable_difference(prob, u, d)
                stuck, slid = contacts(prob, u)
                errors = {r: fd.error(s) for r, s in found.items()}
                for r, e in errors.items():
                    if r != "swapped" and fd.stable:
                        worst[r] = max(worst[r], e)
                mark = " " if fd.stable else "*"
                print(f"{law:13s} {motion:9s} {mu:4.1f} {stuck:4d}/{slid:<4d} "
                      + "".join(f"{errors[r]:9.1e}{mark}" for r in args.routes)
                      + f"   {fd.describe()} [{time.process_time() - t:.0f} s]", flush=True)
    print("*: against quotients that agree over fewer than three decades (a decision switches "
          "within the larger steps): not a claim")
    print("worst where stable: " + ", ".join(f"{r} {e:.1e}" for r, e in worst.items()
                                             if r != "swapped"))


if __name__ == "__main__":
    main()
