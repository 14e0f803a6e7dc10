"""The transcription where the controls are fewer than a force per particle (states and
controls as unknowns, every step a constraint) against the problem's own search in the
controls, on the same problem: misses, effort, iterations, CPU s, peak memory and the gap
between the transcription's positions and its controls' run.

    OMP_NUM_THREADS=1 python benchmarks/fewer_controls.py --maxiter 40 \\
        --cases mesh8:rest,mesh8:blend,mesh8:lbfgsb,toss6:controls,toss6:lbfgsb

A case is PROBLEM:HOW: ``meshR`` is ``mesh_keyframes`` on an R x R sheet with
``control=velocity`` (``rest_band=0.05``, as the positions' benchmarks), ``tossR`` is
``cloth_toss`` at R x R; HOW is a transcription start (``rest``, ``blend``, ``controls``;
``+lm`` for the limited-memory Hessian) or ``lbfgsb`` (L-BFGS-B on the adjoint gradient,
the problem's ``SOLVE`` method).  Each case runs in a process of its own (peak memory is
the process's)."""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time


os.environ.setdefault("OMP_NUM_THREADS", "1")

import casadi_keyframe as ck  # noqa: E402


def build(name: str):
    if name.startswith("mesh"):
        rows = int(name[4:])
        options = {"control": "velocity", "rest_band": 0.05}
        if rows != 12:
            from casadi_keyframe.scenes.mesh_targets import write_sheet_and_targets
            files = write_sheet_and_targets(tempfile.mkdtemp(), rows, rows)
            options.update(cloth=str(files["sheet"]), pins=(0, rows - 1),
                           keyframes=f"40:{files['wave']},80:{files['fold']}")
        return ck.load_problem("mesh_keyframes", **options)
    rows = int(name[4:])
    return ck.load_problem("cloth_toss", rows=rows, cols=rows)


def run_case(case: str, maxiter: int) -> dict:
    name, how = case.split(":")
    prob = build(name)
    t = time.process_time()
    if how == "lbfgsb":
        result = ck.solve(prob, method="lbfgsb", gradient="adjoint", maxiter=maxiter,
                          quiet=True)
    else:
        start, _, lm = how.partition("+")
        result = ck.solve(prob, method="transcription", maxiter=maxiter, quiet=True,
                          options={"start": start,
                                   "hessian": "limited-memory" if lm else "gauss-newton"})
    seconds = time.process_time() - t
    misses = [m.get("rms_position_error", m.get("position_error"))
              for m in result.breakdown["misses"]]
    traj = prob.simulate(result.x, records=False)
    return {"case": case, "misses_mm": [round(1e3 * m, 1) for m in misses],
            "stretch": round(max(prob.model.max_stretch(x) for x in traj.x), 3),
            "control_cost": prob.control_cost(result.x)[0], "iterations": result.nit,
            "cpu_s": round(seconds, 1), "status": result.status,
            "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
            "message": result.message}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--maxiter", type=int, default=40)
    p.add_argument("--cases", default="mesh8:rest,mesh8:lbfgsb")
    p.add_argument("--one", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.one:
        print(json.dumps(run_case(args.one, args.maxiter)))
        return
    print("| case | misses mm | stretch | control cost | iterations | CPU s | peak MB | exit |")
    print("|---|---|---|---|---|---|---|---|")
    messages = []
    for case in args.cases.split(","):
        out = subprocess.run([sys.executable, __file__, "--one", case, "--maxiter",
                              str(args.maxiter)], capture_output=True, text=True)
        if out.returncode:
            print(f"| {case} | failed: {out.stderr.strip().splitlines()[-1]} |||||||", flush=True)
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"| {case} | {'/'.join(map(str, r['misses_mm']))} | {r['stretch']} | "
              f"{r['control_cost']:.3g} | {r['iterations']} | {r['cpu_s']} | "
              f"{r['peak_mb']} | {r['status']} |", flush=True)
        messages.append(f"{case}: {r['message']}")
    print()
    print("\n".join(messages))


if __name__ == "__main__":
    main()
