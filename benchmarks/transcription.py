"""The search in positions (``method="transcription"``) on the mesh walkthrough's 12 x 12 sheet
from each start, against the start itself: keyframe misses, stretch, effort (rms and peak
control acceleration per particle), iterations, CPU seconds, peak memory and how far the
result's run is from the plan it replays.

    .venv/bin/python benchmarks/transcription.py [--maxiter 40] [--only aim,blend,rest,zero]
        [--known 10 [--known-from K]] [--solver sqp|ipopt]

Starts: "aim" the aimed PD controller's motion (the problem's default guess), "blend" the
positions blended between the keyframes' targets, "rest" the start state held still, "zero"
the motion under zero forces (``--set guess=none``).  Every case runs with the rest band of
the zero-force start (``rest_band=0.05``), one BLAS thread, CPU time from
``time.process_time``.

``--known N``: N problems whose targets are reachable by construction, each the 12 x 12
sheet's frames 40 and 80 under random forces smooth in time and over the sheet (rms 6 m/s^2)
with the sheet's weight held (a constant ``m g`` up on every free particle: the walkthrough's
sheet hanging from two corners stretches to 1.385 under gravity alone, past its physical
limit 1.3), the first N seeds whose run stays within the physical limit; solved from the
rest state, each row against the forces that made it by control cost, rms and peak.  These
problems have no strain penalty (their runs stretch past the walkthrough's strain limit 1.2
but not past the physical limit): the search minimises the control cost alone, the measure
it is compared by, and the problem's judge still refuses a result past the physical limit.
Their keyframes count as met within 1 cm (``KNOWN_TOL``).
"""
import argparse
import itertools
import os
import resource
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import casadi_keyframe as ck  # noqa: E402
from casadi_keyframe.meshes import check_mesh  # noqa: E402
from casadi_keyframe.optimize.positions.method import start_positions  # noqa: E402
from casadi_keyframe.optimize.positions.replay import replay_controls  # noqa: E402
from casadi_keyframe.scenes.mesh_cloths import mesh_keyframe_problem  # noqa: E402
from casadi_keyframe.scenes.mesh_targets import hanging_sheet  # noqa: E402

ROWS, KNOWN_RMS = 12, 6.0
KNOWN_TOL = 0.01  # m: the known targets' keyframes are met within 1 cm (their default, 1 %
# of a target's extent, is up to 11.4 mm on these moved sheets)

CASES = {"aim": ("aim", "controls"), "blend": ("none", "blend"), "rest": ("none", "rest"),
         "zero": ("none", "controls")}


def row(name, prob, u, seconds, nit, message=""):
    b = prob.breakdown(u)
    misses = "/".join(f"{1e3 * m['rms_position_error']:.1f}" for m in b["misses"])
    e = b["effort"]
    return (f"| {name} | {misses} mm | {b['physical']['max_stretch']:.3f} | "
            f"{e['rms_acceleration']:.1f} / {e['peak_acceleration']:.0f} | {nit} | "
            f"{seconds:.0f} | {message} |")


def searched(prob, u) -> str:
    """What the search in positions minimises at ``u``: the control cost plus the problem's
    strain penalty."""
    cost = prob.control_cost(u)[0]
    traj = prob.simulate(u, records=False)
    strain = sum(t.value(traj) for t in prob.objective_terms.trajectory_terms
                 if isinstance(t, ck.StrainLimit))
    return f"cost {cost:.3g} + strain {strain:.3g}"


def known_targets(seed: int):
    """``(problem, forces)``: the mesh walkthrough's 12 x 12 sheet with its keyframes at
    frames 40 and 80 of its run under ``forces``, random and smooth in time and over the
    sheet (rms acceleration ``KNOWN_RMS``) plus the sheet's weight held; None when that run
    stretches a spring past the physical limit."""
    base = ck.load_problem("mesh_keyframes", guess="none", rest_band=0.05)
    rng = np.random.default_rng(seed)
    idx = base.controls.idx
    r, c = np.divmod(idx, ROWS)
    t = np.arange(base.steps) / base.steps
    acc = np.zeros((base.steps, idx.size, 3))
    for _ in range(4):
        space = (np.cos(np.pi * rng.integers(0, 3) * r / (ROWS - 1) + rng.uniform(0, np.pi))
                 * np.cos(np.pi * rng.integers(0, 3) * c / (ROWS - 1) + rng.uniform(0, np.pi)))
        wave = np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t + rng.uniform(0, 2 * np.pi))
        acc += wave[:, None, None] * space[None, :, None] * rng.standard_normal(3)
    acc *= KNOWN_RMS / np.sqrt(np.mean(np.sum(acc ** 2, axis=2)))
    acc -= np.asarray(base.model.params.gravity)  # the weight held
    forces = (acc * base.model.masses[idx][None, :, None]).ravel()
    if base.breakdown(forces)["physical"]["max_stretch"] > base.limits.stretch:
        return None
    x = base.simulate(forces, records=False).x
    vertices, quads = hanging_sheet(ROWS, ROWS)
    problem = mesh_keyframe_problem(
        cloth=check_mesh(vertices, quads), keyframes=[(f, check_mesh(x[f], quads))
                                                      for f in (40, 80)],
        steps=None, dt=base.dt, mass=0.3, pinned=base.model.pinned, control="forces",
        colliders=[], weight=100.0, alpha=1e-4, align=False, strain_limit=1.2,
        strain_weight=0.0, wrinkle=0.002, guess="none", rest_band=0.05, tolerance=KNOWN_TOL)
    return problem, forces


def reachable(count: int):
    """The first ``count`` seeds' :func:`known_targets` within the physical limit."""
    seed = 0
    while count > 0:
        made = known_targets(seed)
        if made is not None:
            count -= 1
            yield seed, made
        seed += 1


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--maxiter", type=int, default=40)
    p.add_argument("--only", default=",".join(CASES))
    p.add_argument("--known", type=int, default=0)
    p.add_argument("--known-from", type=int, default=0,
                   help="skip this many of the reachable targets (to split a run)")
    p.add_argument("--solver", default="sqp", choices=("sqp", "ipopt"),
                   help="the transcription's solver option")
    args = p.parse_args()
    print("| case | misses | stretch | rms / peak m/s^2 | iterations | CPU s | outcome |")
    print("|---|---|---|---|---|---|---|")
    for name in [n for n in args.only.split(",") if n]:
        guess, start = CASES[name]
        prob = ck.load_problem("mesh_keyframes", guess=guess, rest_band=0.05)
        u0 = prob.initial_controls()
        if start != "controls":  # the controls that move the sheet along the start's plan
            u0 = replay_controls(prob, start_positions(prob, start, u0)).u
        print(row(f"{name}: the start", prob, u0, 0, 0), flush=True)
        t = time.process_time()
        result = ck.solve(prob, method="transcription", maxiter=args.maxiter,
                          options={"start": start, "solver": args.solver}, quiet=True)
        seconds = time.process_time() - t
        print(row(f"{name}: transcription", prob, result.x, seconds, result.nit,
                  result.message), flush=True)
    for seed, (prob, forces) in itertools.islice(reachable(args.known_from + args.known),
                                                 args.known_from, None):
        print(row(f"known {seed}: the forces ({searched(prob, forces)})", prob, forces, 0, 0),
              flush=True)
        t = time.process_time()
        result = ck.solve(prob, method="transcription", maxiter=args.maxiter,
                          options={"start": "rest", "solver": args.solver},
                          quiet=True)
        seconds = time.process_time() - t
        print(row(f"known {seed}: from rest ({searched(prob, result.x)})", prob, result.x,
                  seconds, result.nit, result.message), flush=True)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak memory of the process: {peak:.0f} MB")


if __name__ == "__main__":
    main()
