"""Which gradient route gets each cloth figure to its keyframes, at full size: the exact hand
adjoint against the paper's integrator-swapping one, each solved as ``casadi-keyframe solve``
solves it (the problem file's ``SOLVE``: method, iterations, coarse meshes first).

    .venv/bin/python benchmarks/cloth_figures.py [--figures cloth_toss cloth_arch cloth_shapes]
        [--routes adjoint swapped] [--set rows=20 --set cols=20] [--json rows.jsonl]

Per run: the stages (particles x iterations), iterations, CPU and wall seconds, how the
search ended, each keyframe's miss (rms over its particles; the toss's centre of mass in
m), the largest spring stretch over every frame (and its frame) and through the last
keyframe (the toss is held to this one, so that a clip that lands, --set steps=72, is judged
by its flight: see its problem file), the deepest
penetration, for the toss how far the sheet has turned at the flip frame, and the verdict
against the targets of issue 14 (toss: centre of mass <= 3 cm, corners <= 0.15 m rms,
turned >= 150 degrees, stretch <= 1.3, <= 15 min; arch <= 1 cm; shapes <= 2 cm each;
stretch <= 1.3).  One BLAS thread; run it alone on the machine for the times.
"""
import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import numpy as np  # noqa: E402

from casadi_keyframe import solve  # noqa: E402
from casadi_keyframe.cli.values import parse_overrides  # noqa: E402
from casadi_keyframe.loading import build_problem, load_module, solve_defaults  # noqa: E402
from casadi_keyframe.optimize.settings import settings_from  # noqa: E402
from casadi_keyframe.scenes.maths import turn_angle  # noqa: E402

FIGURES = ("cloth_toss", "cloth_arch", "cloth_shapes")
STRETCH = 1.3


def run(name: str, route: str, overrides: dict) -> dict:
    module = load_module(name)
    prob = build_problem(module, **overrides)
    asked = settings_from(solve_defaults(module), {"gradient": route})
    cpu, wall = time.process_time(), time.perf_counter()
    r = solve(prob, asked, quiet=True)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    x = r.trajectory.x
    stretch = np.array([prob.model.max_stretch(frame) for frame in x])
    last = max(t.frame for t in prob.objective_terms.state_terms)
    misses = [m.get("rms_position_error", m.get("position_error"))
              for m in r.breakdown["misses"]]
    row = {"figure": name, "particles": prob.model.n, "route": route,
           "stages": [f"{s['particles']}x{s['nit']}" for s in r.stages], "iterations": r.nit,
           "cpu_s": cpu, "wall_s": wall, "status": r.status, "message": r.message,
           "misses": misses, "stretch": float(stretch.max()),
           "stretch_frame": int(stretch.argmax()),
           "stretch_to_last_key": float(stretch[:last + 1].max()),
           "penetration": r.breakdown["physical"].get("max_penetration", 0.0)}
    if name == "cloth_toss":
        row["turned"] = turn_angle(prob.model.rest_positions, x[last], prob.model.masses)
    row["verdict"] = verdict(row)
    return row


def verdict(row) -> str:
    """Which of the issue's targets the run meets ("met", else the ones missed)."""
    misses, checks = row["misses"], []
    if row["figure"] == "cloth_toss":
        # with steps=72 the sheet lands, and the landing tears at dt = 1/60 (see
        # problems/cloth_toss.py): the stretch is checked through the flip frame
        return _verdict([("centre of mass <= 3 cm", misses[0] <= 0.03),
                         ("corners <= 0.15 m", misses[1] <= 0.15),
                         ("turned >= 150 deg", row["turned"] >= 150),
                         ("<= 15 min", row["cpu_s"] <= 900),
                         (f"stretch to the flip <= {STRETCH}",
                          row["stretch_to_last_key"] <= STRETCH)])
    elif row["figure"] == "cloth_arch":
        checks = [("miss <= 1 cm", max(misses) <= 0.01)]
    elif row["figure"] == "cloth_shapes":
        checks = [("every miss <= 2 cm", max(misses) <= 0.02)]
    return _verdict(checks + [(f"stretch <= {STRETCH}", row["stretch"] <= STRETCH)])


def _verdict(checks) -> str:
    missed = [what for what, ok in checks if not ok]
    return "met" if not missed else "MISSED " + ", ".join(missed)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figures", nargs="+", default=list(FIGURES))
    ap.add_argument("--routes", nargs="+", default=["adjoint", "swapped"])
    ap.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="a build override for every figure (e.g. rows=20)")
    ap.add_argument("--json", help="append each run's row to this JSON-lines file")
    args = ap.parse_args()
    overrides = parse_overrides(args.set)
    print(f"{'figure':12} {'n':>5} {'route':8} {'stages':18} {'CPU s':>7} {'misses (m)':26} "
          f"{'stretch':>13} {'to key':>6} {'pen cm':>6} {'turned':>6}  verdict")
    for name in args.figures:
        for route in args.routes:
            row = run(name, route, overrides)
            misses = " / ".join(f"{m:.4f}" for m in row["misses"])
            turned = f"{row['turned']:6.1f}" if "turned" in row else f"{'':6}"
            print(f"{name:12} {row['particles']:5d} {route:8} {' '.join(row['stages']):18} "
                  f"{row['cpu_s']:7.1f} {misses:26} {row['stretch']:6.2f}@{row['stretch_frame']:<6d}"
                  f" {row['stretch_to_last_key']:6.2f} {100 * row['penetration']:6.2f} {turned}"
                  f"  {row['verdict']}", flush=True)
            print(f"{'':12} {row['message'][:110]}", flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
