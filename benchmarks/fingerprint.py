"""Trajectories and gradients of a fixed set of scenes, saved to compare two revisions.

    .venv/bin/python benchmarks/fingerprint.py --save /tmp/before.npz     (on the old checkout)
    .venv/bin/python benchmarks/fingerprint.py --save /tmp/after.npz      (on the new one)
    .venv/bin/python benchmarks/fingerprint.py --compare /tmp/before.npz /tmp/after.npz

A refactoring that should change no result is checked with it: for every array it prints
whether the two runs are bit-identical and, if not, the largest difference relative to the
array's largest entry.  The scenes cover each integrator and gradient route: a flock
(symplectic Euler, exact adjoint), a 6 x 6 sheet with a pin, an attachment, a moving sphere,
a capsule, the ground and self-contact (linearized backward Euler: trajectory, exact adjoint,
swapped adjoint, one tangent pass, CasADi reverse mode; full backward Euler), the toss at
12 x 12, the cape at 6 x 4 from its passive start, and a sheet sticking and sliding on two
bodies with friction (under the guarded and the held collision).  Only public entry points
are used, so the script runs on any revision since the first architecture pass.
"""
import argparse
import os
import sys

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def contact_sheet(integrator, **options):
    from casadi_keyframe import CenterOfMassKeyframe, ControlProblem, Smoothness, StateKeyframe
    from casadi_keyframe.controls import StepForces
    from casadi_keyframe.models import ClothModel
    try:
        from casadi_keyframe.models import Attachment
    except ImportError:  # before the second architecture pass
        from casadi_keyframe.models.cloth import Attachment
    try:
        from casadi_keyframe.models import Capsule, Contact, Plane, Sphere
    except ImportError:  # before the second architecture pass
        from casadi_keyframe.models.colliders import Capsule, Contact, Plane, Sphere

    model = ClothModel.grid(
        6, 6, pinned=[5],
        colliders=[Sphere(lambda t: np.array([0.5, 0.2 - 0.3 * t, -0.7]), 0.2),
                   Capsule((0.1, 0.1, -0.9), (0.9, 0.1, -0.9), 0.05),
                   Plane((0, 0, -1.004))],
        self_contact=Contact(200.0, 0.5, 0.12, 0.05),
        attachments=[Attachment([0], lambda t: np.array([[0.2 * t, 0.1 * t, 0.0]]))], **options)
    x0 = model.rest_positions
    steps = 12
    obj = (StateKeyframe(steps, x=x0 + [0.0, 0.2, 0.05], v=0 * x0)
           + CenterOfMassKeyframe(steps // 2, x=x0.mean(0) + [0, 0.1, 0]) + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=integrator, x0=x0, v0=np.zeros_like(x0),
                          steps=steps, dt=1 / 30, controls=StepForces(), objective=obj,
                          name="contact_sheet")


def friction_sheet(collision):
    """A 5 x 5 sheet thrown across a tilted ground and a rising, turning sphere, both with
    Coulomb friction: particles stick, slide and switch between them within the steps."""
    from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe
    from casadi_keyframe.controls import StepForces
    from casadi_keyframe.integrators import LinearizedBackwardEuler
    from casadi_keyframe.models import ClothModel, Contact, Plane, Sphere

    def spin(t):
        return (np.array([[np.cos(3 * t), -np.sin(3 * t), 0], [np.sin(3 * t), np.cos(3 * t), 0],
                          [0, 0, 1.0]]), np.array([0.45, 0.3, -0.27 + 0.5 * t]))

    ground = Plane((0, 0, 0), (0, -0.2, 1), contact=Contact(friction=0.4))
    ball = Sphere((0, 0, 0), 0.3, contact=Contact(friction=0.5), motion=spin)
    model = ClothModel.grid(5, 5, width=0.6, height=0.6, plane="xy", mass=0.3,
                            colliders=[ground, ball], collision=collision)
    x0 = model.rest_positions + [0, 0, 0.012]
    v0 = np.zeros_like(x0)
    v0[:, 0], v0[:5, 0], v0[:, 2] = 1.0, 0.1, -0.3
    steps = 10
    obj = StateKeyframe(steps, x=x0 + [0.1, 0.05, 0.0]) + Smoothness(1e-4)
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=v0, steps=steps, dt=1 / 60, controls=StepForces(), objective=obj,
                          name="friction_sheet")


def scenes():
    """``{name: (problem, routes, seed)}``."""
    import casadi_keyframe as ck
    from casadi_keyframe.integrators import BackwardEuler, LinearizedBackwardEuler

    return {
        "flock": (ck.load_problem("flock_race", agents=30), ("adjoint",), 1),
        "sheet": (contact_sheet(LinearizedBackwardEuler("direct")),
                  ("adjoint", "swapped", "casadi"), 2),
        "sheet_cholmod": (contact_sheet(LinearizedBackwardEuler("cholmod")),
                          ("adjoint", "swapped"), 2),
        # full backward Euler steps the paper's penalty springs only (since issue 24)
        "sheet_full": (contact_sheet(BackwardEuler("direct", newton_tol=1e-13),
                                     collision="penalty"),
                       ("adjoint",), 3),
        "toss": (ck.load_problem("cloth_toss", rows=12, cols=12), ("adjoint", "swapped"), 4),
        "cape": (ck.load_problem("cape_blend", rows=6, cols=4, guess="passive"),
                 ("adjoint",), 5),
        "friction": (friction_sheet("guarded"), ("adjoint", "casadi"), 6),
        "friction_held": (friction_sheet("constraint"), ("adjoint",), 7),
    }


def fingerprint() -> dict:
    out = {}
    for name, (prob, routes, seed) in scenes().items():
        rng = np.random.default_rng(seed)
        u = prob.initial_controls() + 0.05 * rng.standard_normal(prob.size)
        traj = prob.simulate(u)
        out[f"{name}/x"], out[f"{name}/v"] = traj.x, traj.v
        for route in routes:
            f, g = prob.objective_and_gradient(u, route)
            out[f"{name}/{route}/f"], out[f"{name}/{route}/g"] = np.array(f), g
        du = rng.standard_normal(prob.size)
        out[f"{name}/tangent"] = np.array(prob.directional_derivative(u, du))
        print(f"{name}: {prob.size} controls, routes {', '.join(routes)}", file=sys.stderr)
    return out


def compare(a_path: str, b_path: str) -> int:
    a, b = np.load(a_path), np.load(b_path)
    worst = 0.0
    for key in sorted(set(a.files) | set(b.files)):
        if key not in a.files or key not in b.files:
            print(f"{key:28s} only in {'after' if key in b.files else 'before'}")
            continue
        x, y = a[key], b[key]
        if x.shape != y.shape:
            print(f"{key:28s} shapes differ: {x.shape} vs {y.shape}")
            worst = np.inf
            continue
        if np.array_equal(x, y):
            print(f"{key:28s} identical")
            continue
        rel = float(np.max(np.abs(x - y)) / max(np.max(np.abs(x)), 1e-300))
        worst = max(worst, rel)
        print(f"{key:28s} max |difference| / max |before| = {rel:.2e}")
    print(f"largest relative difference: {worst:.2e}")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", metavar="NPZ")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    args = ap.parse_args()
    if args.compare:
        return compare(*args.compare)
    if not args.save:
        ap.error("give --save NPZ or --compare BEFORE AFTER")
    np.savez(args.save, **fingerprint())
    return 0


if __name__ == "__main__":
    sys.exit(main())
