"""Searches and command-line runs of a fixed set, every number they return saved, to compare
two revisions (benchmarks/fingerprint.py does the same for trajectories and gradients).

    .venv/bin/python benchmarks/search_fingerprint.py --save /tmp/before.json  (old checkout)
    .venv/bin/python benchmarks/search_fingerprint.py --save /tmp/after.json   (new one)
    .venv/bin/python benchmarks/search_fingerprint.py --compare /tmp/before.json /tmp/after.json

A refactoring of the optimizer that should change no search is checked with it: each case's
controls, objective, gradient, iterations, evaluations, status, message, stages, history
and trajectory (a command-line run's summary.json, result and printout), times left out,
must be identical.  The cases cover every method, continuation, the finish and its two
searches alone, the rounds, multiple shooting (penalty, Gauss-Newton, IPOPT form), the
swapped route, and runs with resolutions, rounds, shooting and a finish.  Run it from the
repository's root (it reuses the tests' small problems).
"""
import argparse
import contextlib
import hashlib
import io
import itertools
import json
import os
import re
import sys
import tempfile
import warnings

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
warnings.simplefilter("ignore")

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, ROOT)

TIMED = {"seconds", "wall_seconds", "evaluation_seconds", "stage_seconds"}


def clean(obj):
    """``obj`` as JSON can hold it: arrays by their bytes' hash, floats exactly, times out."""
    if isinstance(obj, dict):
        return {k: clean(v) for k, v in obj.items() if k not in TIMED}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return {"sha": hashlib.sha1(np.ascontiguousarray(obj).tobytes()).hexdigest(),
                "norm": float(np.linalg.norm(obj))}
    if isinstance(obj, (np.floating, float)):
        return float(obj).hex()
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def record(res):
    """What a Result says, as :func:`clean` keeps it (a duration in its message read T)."""
    import re
    msg = re.sub(r"\d+\.\d s", "T s", res.message)
    return clean({"x": res.x, "fun": res.fun, "jac": res.jac, "nit": res.nit, "nfev": res.nfev,
                  "njev": res.njev, "status": res.status, "message": msg,
                  "method": res.method, "gradient": str(res.gradient),
                  "stages": res.stages, "history": res.history,
                  "traj": res.trajectory.x})


def cases():
    """``(name, run)`` pairs: ``run()`` returns a Result."""
    from helpers import small_flock
    from test_augmented_lagrangian import swing
    from test_finish import tight
    from test_shooting import sheet_problem
    from casadi_keyframe import load_problem
    from casadi_keyframe.optimize import solve, solve_augmented, lower_effort
    try:
        from casadi_keyframe.optimize.finish import land
    except ImportError:  # before the fourth architecture pass
        from casadi_keyframe.optimize.constrained import land

    flock = small_flock()
    race = load_problem("flock_race", agents=8, steps=40)
    yield "lbfgsb_flock", lambda: solve(flock, maxiter=20, quiet=True, stop="method")
    yield "ipopt_flock", lambda: solve(flock, "ipopt", maxiter=8, quiet=True, stop="method")
    yield "gn_race", lambda: solve(race, "gauss-newton", maxiter=6, quiet=True)
    yield "gn_race_radius", lambda: solve(race, "gauss-newton", maxiter=4, quiet=True,
                                          options={"radius": 0.5, "plane": False})
    yield "ls_race", lambda: solve(race, "least-squares", maxiter=4, quiet=True,
                                   options={"lsmr_maxiter": 10})
    yield "cont_race", lambda: solve(race, maxiter=5, quiet=True, continuation=[0.25])
    prob = tight(swing())
    yield "finish_land", lambda: solve(prob, maxiter=50, quiet=True, finish="land")
    yield "finish_effort", lambda: solve(prob, maxiter=50, quiet=True, finish="effort,maxiter=3")
    yield "finish_gn", lambda: solve(prob, "gauss-newton", maxiter=10, quiet=True,
                                     finish="effort,window=6,maxiter=2")
    short = solve(prob, maxiter=50, quiet=True)
    yield "land", lambda: land(prob, u0=short.x)
    landed = land(prob, u0=short.x)
    yield "lower_effort", lambda: lower_effort(prob, u0=landed.x, maxiter=3)
    yield "augmented", lambda: solve_augmented(swing(), rounds=2, maxiter=30, quiet=True,
                                               stop="method")
    sheet = sheet_problem(ground=False)
    yield "shoot", lambda: solve(sheet, maxiter=20, quiet=True, stop="method",
                                 shooting={"segments": 3, "init": "blend", "rounds": 2})
    yield "shoot_gn", lambda: solve(sheet, "gauss-newton", maxiter=6, quiet=True,
                                    shooting={"segments": 3, "init": "guess", "rounds": 1})
    yield "shoot_ipopt", lambda: solve(sheet, maxiter=6, quiet=True, stop="method",
                                       shooting={"segments": 3, "init": "blend",
                                                 "formulation": "ipopt", "polish": False})
    yield "swapped_sheet", lambda: solve(sheet, maxiter=8, quiet=True, gradient="swapped",
                                         stop="method")


RUNS = {  # casadi-keyframe solve ARGS, each with --out, --quiet, no animation or viewer
    "cli_race": ["flock_race", "--set", "agents=8", "--set", "steps=40", "--maxiter", "4"],
    "cli_race_gn": ["flock_race", "--set", "agents=8", "--set", "steps=40", "--maxiter", "3",
                    "--method", "gauss-newton"],
    "cli_rounds": ["flock_race", "--set", "agents=8", "--set", "steps=40", "--maxiter", "3",
                   "--rounds", "2", "--weight-growth", "2"],
    "cli_shapes": ["cloth_shapes", "--set", "rows=4", "--set", "cols=4", "--set", "steps=12",
                   "--maxiter", "3"],
    "cli_shoot": ["flock_race", "--set", "agents=8", "--set", "steps=40", "--maxiter", "4",
                  "--segments", "2", "--shooting", "rounds=2"],
    "cli_limit_finish": ["cloth_shapes", "--set", "rows=4", "--set", "cols=4", "--set",
                         "steps=12", "--maxiter", "3", "--resolution", "none",
                         "--finish", "land,window=4,maxiter=2", "--stop", "method"],
}


def command_line_run(args) -> dict:
    """A whole command-line run: its exit code, summary.json (times and paths out), the
    controls written and what it printed (times read T)."""
    from casadi_keyframe.cli import main as cli

    with tempfile.TemporaryDirectory() as out:
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(io.StringIO()):
            code = cli(["solve", *args, "--out", out, "--quiet", "--no-animation",
                        "--no-viewer"])
        with open(os.path.join(out, "summary.json")) as f:
            summary = json.load(f)
        with np.load(os.path.join(out, "result.npz")) as data:
            x = data["x"]
    for where in ("problem_file", "folder"):  # the checkout's own paths
        summary.pop(where, None)
    text = re.sub(r"wall [0-9.]+ s", "wall T s", printed.getvalue())
    text = re.sub(r"[0-9.]+ s(;|,|$)", r"T s\1", text).replace(out, "OUT").replace(ROOT, "ROOT")
    return clean({"code": code, "summary": summary, "x": x, "printed": text})


def save(path) -> None:
    out = {}
    runs = ((name, lambda a=a: command_line_run(a)) for name, a in RUNS.items())
    for name, run in itertools.chain(cases(), runs):
        try:
            got = run()
            out[name] = got if isinstance(got, dict) else record(got)
        except Exception as err:  # noqa: BLE001 (a case that fails is recorded as failing)
            out[name] = {"error": f"{type(err).__name__}: {err}"}
        said = out[name].get("message", out[name].get("error", ""))
        print(f"{name:18s} nit {out[name].get('nit')} status "
              f"{out[name].get('status', out[name].get('code'))}: {str(said)[:100]}",
              flush=True)
    with open(path, "w") as f:
        json.dump(out, f, indent=1)


def compare(before_path, after_path) -> int:
    with open(before_path) as f:
        before = json.load(f)
    with open(after_path) as f:
        after = json.load(f)
    differ = 0
    for name, old in before.items():
        new = after.get(name)
        if new == old:
            print(f"{name:18s} identical")
            continue
        differ += 1
        for key in old if new is not None else ["(missing)"]:
            if new is None or old.get(key) != new.get(key):
                print(f"{name:18s} {key} differs:\n  {str(old.get(key))[:400]}\n  "
                      f"{str((new or {}).get(key))[:400]}")
    print("every case identical" if not differ else f"{differ} cases differ")
    return 1 if differ else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--save", metavar="JSON")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    args = parser.parse_args(argv)
    if args.save:
        save(args.save)
        return 0
    if args.compare:
        return compare(*args.compare)
    parser.error("give --save or --compare")


if __name__ == "__main__":
    sys.exit(main())
