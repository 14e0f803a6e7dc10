"""The cape from rest (fig. 6, ``cape_blend``) by the search in positions: the issue 40
targets (within 6 mm and 5 cm/s, stretch at most 1.3, nothing inside the body, 10 CPU
minutes, the replay within 0.1 mm) measured on the search's own iterations.

    .venv/bin/python benchmarks/cape_transcription.py [--rows 26 --cols 16] [--start rest]
        [--maxiter 60] [--cpu-limit 600] [--linear auto] [--rest-band 0]

The problem is built with ``guess="passive"`` and ``collision="penalty"`` (the contact the
inverse step writes); the search is the one ``--method transcription`` runs
(:class:`~casadi_keyframe.optimize.positions.sqp.PositionSQP` on the transcription, the
keyframe's position and velocity held within 0.9 of their tolerances), stopped at
``--maxiter`` or once its CPU time passes ``--cpu-limit``.  Printed: one line per iteration
(effort, violation, misses, damping, kept, share, ratio, CPU s), then the start and the last
kept plan, each replayed through the problem's own step (:mod:`.replay`) and judged on that
run: misses in mm and cm/s, largest stretch, deepest particle inside a body (mm), rms / peak
control acceleration per particle (m/s^2), and the largest distance between the run of the
returned controls and the plan at any frame.  One BLAS thread, CPU from
``time.process_time``, peak memory the process's.
"""
import argparse
import os
import resource
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import casadi_keyframe as ck  # noqa: E402
from casadi_keyframe.optimize.finish.constraint import control_hessian  # noqa: E402
from casadi_keyframe.optimize.positions import Transcription  # noqa: E402
from casadi_keyframe.optimize.positions.goal import goal_constraints  # noqa: E402
from casadi_keyframe.optimize.positions.linear_solve import LinearChoice  # noqa: E402
from casadi_keyframe.optimize.positions.method import start_positions  # noqa: E402
from casadi_keyframe.optimize.positions.replay import replay_controls  # noqa: E402
from casadi_keyframe.optimize.positions.sqp import PositionSQP  # noqa: E402


def judged(prob, tr, z) -> str:
    """The plan ``z`` replayed and judged (module docstring), as table cells."""
    plan = tr.frames(z)
    replay = replay_controls(prob, plan)
    run = prob.simulate(replay.u, records=False).x
    off = float(np.max(np.linalg.norm(run - plan, axis=2)))
    b = prob.breakdown(replay.u)
    miss = b["misses"][0]
    phys, effort = b["physical"], b["effort"]
    return (f"{1e3 * miss['rms_position_error']:.1f} mm / "
            f"{1e2 * miss['rms_velocity_error']:.1f} cm/s | {phys['max_stretch']:.3f} | "
            f"{1e3 * phys.get('max_penetration', 0.0):.1f} | "
            f"{effort['rms_acceleration']:.1f} / {effort['peak_acceleration']:.0f} | "
            f"{1e3 * off:.1e} mm")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rows", type=int, default=26)
    p.add_argument("--cols", type=int, default=16)
    p.add_argument("--start", default="rest", choices=("rest", "blend", "controls"))
    p.add_argument("--maxiter", type=int, default=60)
    p.add_argument("--cpu-limit", type=float, default=600.0)
    p.add_argument("--linear", default="auto", choices=("auto", "direct", "iterative"))
    p.add_argument("--rest-band", type=float, default=0.0)
    args = p.parse_args()
    begun = time.process_time()
    prob = ck.load_problem("cape_blend", rows=args.rows, cols=args.cols, guess="passive",
                           collision="penalty", rest_band=args.rest_band)
    tr = Transcription(prob)
    z0 = tr.unknowns(start_positions(prob, args.start, prob.initial_controls()))
    sqp = PositionSQP(tr, goal_constraints(tr), control_hessian(prob), LinearChoice(args.linear))
    print(f"cape_blend {args.rows} x {args.cols}, {prob.steps} steps, {tr.size} unknowns, "
          f"start {args.start}, linear {args.linear}; built in "
          f"{time.process_time() - begun:.1f} s CPU")
    print("| it | effort | violation | misses mm, mm/s | mu | kept | theta | ratio | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    t0, kept = time.process_time(), [z0]

    def each(report, point):
        if report.kept:
            kept.append(point.z)
        misses = "/".join(f"{1e3 * m:.1f}" for m in report.misses)
        print(f"| {report.iteration} | {report.effort:.4g} | {report.violation:.3g} | "
              f"{misses} | {report.mu:.1e} | {'yes' if report.kept else 'no'} | "
              f"{report.theta:.3g} | {report.ratio:.3g} | {time.process_time() - t0:.0f} |",
              flush=True)

    outcome, _ = sqp.run(z0, maxiter=args.maxiter, tol=1e-3, on_iteration=each,
                         should_stop=lambda: time.process_time() - t0 > args.cpu_limit)
    seconds = time.process_time() - t0
    print(f"\nended: {outcome.reason} after {outcome.iterations} iterations, {seconds:.0f} s "
          f"CPU ({len(kept) - 1} kept)\n")
    print("| plan | misses | stretch | in body mm | rms / peak m/s^2 | replay vs plan |")
    print("|---|---|---|---|---|---|")
    print(f"| the start ({args.start}) | {judged(prob, tr, z0)} |")
    print(f"| the last kept | {judged(prob, tr, kept[-1])} |")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak memory of the process: {peak:.0f} MB")


if __name__ == "__main__":
    main()
