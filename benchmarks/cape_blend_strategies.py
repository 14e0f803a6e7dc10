"""How close does each strategy bring the cape blend from rest (problems/cape_blend.py,
``guess=passive``) to its keyframe, and at what cost?

Per strategy: the final miss over the free particles (rms position in m and as a fraction of
the cape's 0.6 m width, rms velocity in m/s), whether the blend stays physical (largest
spring stretch, deepest particle in the body in cm, by ``clip_report``), iterations, CPU
seconds (this process and its shooting workers) and wall seconds, and how the search ended.
Strategies (``--only``; the issue's table is the default set):

* ``single``: one gradient through the whole blend, L-BFGS-B (the paper's method);
* ``single+ipopt``: the same with IPOPT;
* ``ms3``, ``ms6``, ``ms12``: multiple shooting with K segments, the defects held by
  multipliers over L-BFGS-B rounds, nodes blended from the passive run to the target,
  then the single-shooting polish;
* ``ms6+nlp``: K = 6 with the defects as IPOPT's constraints (their Jacobian by one
  backward sweep per row; slow beyond small capes: use ``--time-limit``);
* ``ms6+2workers``: ``ms6`` with its segments swept by 2 worker processes;
* ``single+homotopy``, ``ms6+homotopy``: first with the body's contact ``--softness``
  times softer and thicker (``contact`` override), then the model's own;
* ``ms6+passive``, ``ms6+target``: ``ms6`` with its nodes on the passive run or the target;
* ``ms3+path``, ``ms6+path``, ``ms12+path`` (``+2workers``, ``+homotopy``, ``+nlp``): nodes on the
  problem's reference path (``cape_blend.path``: the cape held in the torso's frame
  crossfaded into the walk clip's), as its ``SOLVE`` does from rest;
* ``tracking``: the problem's default start, the PD tracking guess, for reference.

    .venv/bin/python benchmarks/cape_blend_strategies.py [--rows 8 --cols 6] [--maxiter 200]
        [--time-limit 1800] [--softness 3] [--only single ms6 ...] [--toss 50]

``--toss N`` also compares single and multiple shooting (K = 3) on ``cloth_toss`` at N x N.
Each strategy gets ``--maxiter`` iterations per stage.  ``--json FILE`` appends each row as
a JSON line.  ``--time-limit`` is wall time: on a shared machine CPU is the figure to compare.
"""
import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from casadi_keyframe import load_problem, solve  # noqa: E402
from casadi_keyframe.loading import load_module  # noqa: E402
from casadi_keyframe.optimize import STATUS  # noqa: E402
from casadi_keyframe.scenes.capes import clip_report  # noqa: E402

WIDTH = 0.6  # m, the cape's width (cape_model's default)
STRATEGIES = {
    "single": {},
    "single+ipopt": {"method": "ipopt"},
    "ms3": {"shooting": {"segments": 3, "init": "blend"}},
    "ms6": {"shooting": {"segments": 6, "init": "blend"}},
    "ms12": {"shooting": {"segments": 12, "init": "blend"}},
    "ms6+nlp": {"shooting": {"segments": 6, "init": "blend", "formulation": "ipopt"}},
    "ms6+2workers": {"shooting": {"segments": 6, "init": "blend", "workers": 2}},
    "single+homotopy": {"homotopy": True},
    "ms6+homotopy": {"shooting": {"segments": 6, "init": "blend"}, "homotopy": True},
    "ms6+passive": {"shooting": {"segments": 6, "init": "passive"}},
    "ms6+target": {"shooting": {"segments": 6, "init": "target"}},
    "ms3+path": {"shooting": {"segments": 3, "init": "path"}},
    "ms6+path": {"shooting": {"segments": 6, "init": "path"}},
    "ms12+path": {"shooting": {"segments": 12, "init": "path"}},
    "ms6+path+2workers": {"shooting": {"segments": 6, "init": "path", "workers": 2}},
    "ms6+path+nlp": {"shooting": {"segments": 6, "init": "path", "formulation": "ipopt"}},
    "ms6+path+homotopy": {"shooting": {"segments": 6, "init": "path"}, "homotopy": True},
    "tracking": {"guess": "tracking"},
}
DEFAULT = ["single", "single+ipopt", "ms3", "ms6", "ms12", "ms6+2workers", "single+homotopy",
           "ms6+homotopy"]


def free_misses(prob, traj) -> dict:
    """Final position and velocity misses over the free particles (the sewn-on ones follow
    the transition and are not the optimizer's to move)."""
    term = prob.objective_terms.state_terms[0]
    free = prob.controls.idx
    dx = np.linalg.norm(traj.x[-1, free] - term.position_target[free], axis=1)
    dv = np.linalg.norm(traj.v[-1, free] - term.velocity_target[free], axis=1)
    rms = float(np.sqrt((dx ** 2).mean()))
    return {"rms_x": rms, "width_fraction": rms / WIDTH, "rms_v": float(np.sqrt((dv ** 2).mean()))}


def cpu_seconds() -> float:
    """CPU seconds of this process and its ended children (the shooting workers)."""
    me, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def run(name, build, maxiter, time_limit, softness) -> dict:
    """Solve the strategy ``name``; a row of figures."""
    spec = dict(STRATEGIES[name])
    prob = build(guess=spec.pop("guess", "passive"))
    homotopy = [{"contact": softness}] if spec.pop("homotopy", False) else None
    if spec.get("shooting", {}).get("init") == "path":
        spec["shooting"] = {**spec["shooting"], "init": load_module("cape_blend").path}
    start = free_misses(prob, prob.simulate(prob.initial_controls(), records=False))
    wall, cpu = time.perf_counter(), cpu_seconds()
    res = solve(prob, spec.pop("method", "lbfgsb"), maxiter=maxiter, quiet=True,
                time_limit=time_limit, homotopy=homotopy, **spec)
    wall, cpu = time.perf_counter() - wall, cpu_seconds() - cpu
    report = clip_report(prob.model, res.trajectory)
    defect = [s["defect"] for s in res.stages if "defect" in s]
    return {**report, **free_misses(prob, res.trajectory), "strategy": name,
            "start": start["rms_x"], "nit": res.nit, "cpu": cpu, "wall": wall,
            "status": STATUS[res.status], "defect": defect[-1] if defect else None}


HEAD = (f"{'strategy':16s} {'start m':>7s} {'rms x m':>8s} {'/width':>7s} {'rms v':>7s} "
        f"{'stretch':>7s} {'in body':>8s} {'nit':>5s} {'cpu s':>7s} {'wall s':>7s} "
        f"{'defect':>7s}  status")


def row(r) -> str:
    defect = "-" if r["defect"] is None else f"{r['defect']:.3g}"
    return (f"{r['strategy']:16s} {r['start']:7.3g} {r['rms_x']:8.3g} {r['width_fraction']:7.2%} "
            f"{r['rms_v']:7.3g} {r['max_stretch']:7.3g} {100 * r['penetration']:6.3g}cm "
            f"{r['nit']:5d} {r['cpu']:7.0f} {r['wall']:7.0f} {defect:>7s}  {r['status']}")


def toss(size: int, maxiter: int, time_limit) -> None:
    """Single against multiple shooting (K = 3) on cloth_toss at ``size`` x ``size``."""
    prob = load_problem("cloth_toss", rows=size, cols=size)
    print(f"\ncloth_toss {size} x {size}: corners' rms miss, ring miss, stretch, iterations, "
          f"CPU s, wall s")
    for name, shooting in (("single", None), ("ms3", {"segments": 3, "init": "passive"})):
        wall, cpu = time.perf_counter(), cpu_seconds()
        res = solve(prob, maxiter=maxiter, quiet=True, time_limit=time_limit, shooting=shooting)
        ring, corners = res.breakdown["misses"]
        print(f"{name:8s} corners {corners['rms_position_error']:.3g} m  ring "
              f"{ring['position_error']:.3g} m  stretch {res.breakdown['physical']['max_stretch']:.3g}"
              f"  nit {res.nit}  cpu {cpu_seconds() - cpu:.0f}  wall "
              f"{time.perf_counter() - wall:.0f}  {STATUS[res.status]}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=8)
    ap.add_argument("--cols", type=int, default=6)
    ap.add_argument("--window", type=float, default=1.0)
    ap.add_argument("--maxiter", type=int, default=200)
    ap.add_argument("--time-limit", type=float, default=None, help="seconds per strategy")
    ap.add_argument("--softness", type=float, default=3.0, help="the homotopy's first contact")
    ap.add_argument("--only", nargs="*", default=DEFAULT, choices=list(STRATEGIES))
    ap.add_argument("--toss", type=int, default=0, help="also cloth_toss at N x N")
    ap.add_argument("--json", help="append each row to this JSON-lines file")
    args = ap.parse_args(argv)

    def build(**kw):
        return load_problem("cape_blend", rows=args.rows, cols=args.cols, window=args.window,
                            **kw)

    size = "" if (args.rows, args.cols) == (26, 16) else " (reduced: the problem's is 26 x 16)"
    print(f"cape_blend {args.rows} x {args.cols}{size} from rest, window {args.window} s, "
          f"{args.maxiter} iterations per stage"
          + (f", {args.time_limit:g} s at most" if args.time_limit else ""))
    print(HEAD)
    for name in args.only:
        r = run(name, build, args.maxiter, args.time_limit, args.softness)
        print(row(r), flush=True)
        if args.json:
            with open(args.json, "a") as f:
                f.write(json.dumps({**r, "rows": args.rows, "cols": args.cols,
                                    "maxiter": args.maxiter,
                                    "time_limit": args.time_limit}) + "\n")
    if args.toss:
        toss(args.toss, args.maxiter, args.time_limit)


if __name__ == "__main__":
    main()
