"""Pins that follow an animation, from the command line: a 12 x 12 sheet whose top row is
carried 0.5 m sideways over 60 frames (a PC2 cache beside its rest OBJ, written by
``scenes.mesh_targets.write_carried_sheet``) solved onto the wave carried as far at frame 60.
Prints how far the pinned vertices are from the file at any frame when the result is
replayed through ``simulate``, the keyframe's miss against its tolerance, and the exit code.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/pin_motion_sheet.py [--rows 12]
        [--frames 60] [--shift 0.5] [--keep FOLDER]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from casadi_keyframe.cli import main
from casadi_keyframe.export.pc2 import read_pc2
from casadi_keyframe.loading import load_problem
from casadi_keyframe.scenes.mesh_targets import write_carried_sheet


def run(folder: Path, rows: int, frames: int, shift: float) -> None:
    files = write_carried_sheet(folder, rows, rows, frames, shift=(shift, 0.0, 0.0))
    top = ",".join(str(i) for i in range(rows))
    sets = {"cloth": str(files["sheet"]), "keyframes": f"{frames}:{files['wave']}", "pins": top,
            "pin_motion": str(files["motion"])}
    args = ["solve", "mesh_keyframes", "--out", str(folder / "run"), "--quiet",
            "--no-animation", "--no-viewer"]
    args += [a for k, v in sets.items() for a in ("--set", f"{k}={v}")]
    print("casadi-keyframe " + " ".join(args))
    start = time.process_time()
    code = main(args)
    seconds = time.process_time() - start
    saved = np.load(folder / "run" / "result.npz")
    prob = load_problem("mesh_keyframes", **{**sets, "pins": tuple(range(rows))})
    replay = prob.simulate(saved["u"], records=False)
    motion = read_pc2(files["motion"])[0]
    gap = np.linalg.norm(replay.x[:, :rows] - motion[:, :rows], axis=2).max(axis=1)
    summary = json.loads((folder / "run" / "summary.json").read_text())
    miss = summary["breakdown"]["misses"][0]
    term = next(t for t in prob.objective_terms.state_terms)
    print(f"{rows} x {rows} sheet, top row carried {shift} m over {frames} frames: exit {code}, "
          f"{summary['status_name']} after {summary['nit']} iterations, {seconds:.1f} s CPU")
    print(f"  pins vs the file, replayed through simulate: largest gap {gap.max():.3g} m "
          f"(frame {int(gap.argmax())}), every frame within 1e-6 m: {bool(gap.max() <= 1e-6)}")
    print(f"  replay equals the saved result bit for bit: {np.array_equal(replay.x, saved['x'])}")
    tolerance = term.within[0]
    print(f"  keyframe at frame {frames}: rms miss {miss['rms_position_error'] * 1e3:.3g} mm "
          f"(tolerance {tolerance * 1e3:.3g} mm), max {miss['max_position_error'] * 1e3:.3g} "
          f"mm; within its tolerance: {term.shortfall(replay) is None}")
    print(f"  physical: largest stretch {summary['breakdown']['physical']['max_stretch']:.3g}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=12)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--shift", type=float, default=0.5)
    parser.add_argument("--keep", type=Path, help="write the files and the run here")
    args = parser.parse_args()
    if args.keep:
        run(args.keep, args.rows, args.frames, args.shift)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            run(Path(tmp), args.rows, args.frames, args.shift)
