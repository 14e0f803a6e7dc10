"""How close does each strategy bring the cape blend (problems/cape_blend.py) to its keyframe?

Per strategy: iterations, evaluations, wall seconds, objective, control cost, the final
miss over the free particles: rms position miss (m, and as a fraction of the cape's 0.6 m
width), largest position miss, rms velocity miss (m/s); and whether the blend stays
physical: the largest spring stretch and the deepest particle in the body (cm).
Strategies:

* ``passive``: the paper's start (zero forces) with L-BFGS-B and the exact hand adjoint;
* ``swapped``: the same with the paper's integrator-swapping adjoint;
* ``ipopt``: the passive start with IPOPT (limited-memory Hessian) instead of L-BFGS-B;
* ``continuation``: the same, first at 2 dt;
* ``schedule``: keyframe weight x10 per round, 3 rounds (``--growth``, ``--rounds``;
  :func:`solve_augmented` without multipliers);
* ``multipliers``: augmented Lagrangian with the same weight schedule;
* ``tracking``: the problem's default start, the PD tracking guess that lands by inverse
  steps, then L-BFGS-B;
* ``tracking+multipliers``: the tracking guess, then 3 augmented-Lagrangian rounds;
* ``tracking+soft``: the same with the keyframe weights 100 times lower in the first round
  (x10 per round back to the problem's), so that the first round can trade the landing for
  lower forces and the multipliers bring it back;
* ``tracking+ipopt``: the tracking guess, then IPOPT;
* ``coarse+ipopt``: the passive start with IPOPT on a cape of half the rows and columns
  first (``solve(..., resolutions=...)``), its forces carried to the full mesh;
* ``tracking+lower_effort``: the tracking guess, then
  :func:`~casadi_keyframe.optimize.constrained.lower_effort` (the landing held within 1 mm and 5 cm/s
  rms as a constraint while the control cost falls; ``--effort-steps`` kept steps at most,
  on the last ``--effort-window`` steps).

    .venv/bin/python benchmarks/cape_blend_strategies.py [--rows 8 --cols 6] [--window 1.0]
        [--maxiter 100] [--rounds 3] [--growth 10] [--effort-steps 5] [--effort-window 12]
        [--only passive tracking ...]

Each strategy gets ``--maxiter`` L-BFGS-B iterations in all (split over rounds or stages).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from casadi_keyframe import load_problem, solve  # noqa: E402
from casadi_keyframe.optimize import lower_effort, solve_augmented  # noqa: E402
from casadi_keyframe.scenes.capes import clip_report  # noqa: E402

WIDTH = 0.6  # m, the cape's width (cape_model's default)


def free_misses(prob, traj) -> dict:
    """Final position and velocity misses over the free particles (the sewn-on ones follow
    the transition and are not the optimizer's to move)."""
    term = prob.objective_terms.state_terms[0]
    free = prob.controls.idx
    dx = np.linalg.norm(traj.x[-1, free] - term.position_target[free], axis=1)
    dv = np.linalg.norm(traj.v[-1, free] - term.velocity_target[free], axis=1)
    rms = float(np.sqrt((dx ** 2).mean()))
    return {"rms_x": rms, "width_fraction": rms / WIDTH, "max_x": float(dx.max()),
            "rms_v": float(np.sqrt((dv ** 2).mean()))}


def run(name, build, maxiter, rounds=3, growth=10.0, effort=(5, 12), coarse=None):
    """Build the strategy's problem and solve it; a row of figures (``effort``:
    lower_effort's kept steps at most and window; ``coarse``: the build overrides of
    coarse+ipopt's first mesh)."""
    per_round = max(maxiter // rounds, 1)
    if name == "swapped":
        prob = build(guess="passive", adjoint="swapped")
    elif name == "tracking+soft":
        prob = build(position_weight=4.0, velocity_weight=0.04)
    else:
        prob = build(guess="tracking" if name.startswith("tracking") else "passive")
    start_misses = free_misses(prob, prob.simulate(prob.initial_controls()))
    start, cpu = time.perf_counter(), time.process_time()
    if name == "tracking+lower_effort":
        res = lower_effort(prob, maxiter=effort[0], window=effort[1])
    elif name in ("passive", "swapped", "tracking"):
        res = solve(prob, maxiter=maxiter, quiet=True)
    elif name == "coarse+ipopt":
        res = solve(prob, "ipopt", maxiter=maxiter, quiet=True, resolutions=[coarse])
    elif name.endswith("ipopt"):
        res = solve(prob, "ipopt", maxiter=maxiter, quiet=True)
    elif name == "continuation":
        res = solve(prob, maxiter=maxiter // 2, quiet=True, continuation=[2 * prob.dt])
    else:
        res = solve_augmented(prob, rounds=rounds, weight_growth=growth,
                              multipliers=name != "schedule", maxiter=per_round, quiet=True)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    score = build(guess="passive") if name == "tracking+soft" else prob  # default weights
    report = clip_report(prob.model, res.trajectory)
    return {**report, "strategy": name, "nit": res.nit, "nfev": res.nfev, "seconds": seconds,
            "cpu": cpu, "start_control": prob.control_cost(prob.initial_controls())[0],
            "objective": score.objective(res.x), "control": res.breakdown["control_cost"],
            **free_misses(prob, res.trajectory), "start": start_misses}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=8)
    ap.add_argument("--cols", type=int, default=6)
    ap.add_argument("--window", type=float, default=1.0)
    ap.add_argument("--maxiter", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the round strategies")
    ap.add_argument("--growth", type=float, default=10.0, help="weight factor per round")
    ap.add_argument("--only", nargs="*", default=["passive", "swapped", "ipopt", "continuation",
                                                  "schedule", "multipliers", "tracking",
                                                  "tracking+multipliers", "tracking+soft",
                                                  "tracking+ipopt", "tracking+lower_effort",
                                                  "coarse+ipopt"])
    ap.add_argument("--effort-steps", type=int, default=5, help="lower_effort's maxiter")
    ap.add_argument("--effort-window", type=int, default=12, help="lower_effort's window")
    args = ap.parse_args(argv)

    def build(**kw):
        return load_problem("cape_blend", rows=args.rows, cols=args.cols, window=args.window,
                            **kw)

    print(f"cape_blend {args.rows} x {args.cols}, window {args.window} s, "
          f"{args.maxiter} iterations per strategy, rounds {args.rounds} x{args.growth:g}")
    print(f"{'strategy':22s} {'start rms':>9s} {'nit':>4s} {'nfev':>5s} {'s':>6s} "
          f"{'objective':>10s} {'control':>8s} {'rms x m':>8s} {'/width':>7s} {'max x':>7s} "
          f"{'rms v':>7s} {'stretch':>7s} {'in body':>7s} {'cpu s':>6s} {'control/start':>13s}")
    for name in args.only:
        r = run(name, build, args.maxiter, args.rounds, args.growth,
                (args.effort_steps, args.effort_window),
                {"rows": max(args.rows // 2, 2), "cols": max(args.cols // 2, 3)})
        print(f"{name:22s} {r['start']['rms_x']:9.3g} {r['nit']:4d} {r['nfev']:5d} "
              f"{r['seconds']:6.0f} {r['objective']:10.4g} {r['control']:8.3g} "
              f"{r['rms_x']:8.3g} {r['width_fraction']:7.2%} {r['max_x']:7.3g} "
              f"{r['rms_v']:7.3g} {r['max_stretch']:7.3g} {100 * r['penetration']:5.2g}cm "
              f"{r['cpu']:6.0f} {change(r['control'], r['start_control']):>13s}", flush=True)


def change(value: float, start: float) -> str:
    """``"-22.8%"``: the control cost's change from a start that has one ("-" from zero)."""
    return f"{value / start - 1:+.1%}" if start > 0 else "-"


if __name__ == "__main__":
    main()
