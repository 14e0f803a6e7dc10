"""Re-solving the last frames of a shot after its last keyframe changed, against solving the
whole shot again: the CPU time of each, their ratio, whether the kept frames are bit for bit
the first run's, and whether the new keyframe is hit.

A 12 x 12 sheet (mesh_keyframes) hits a wave at frame 40 and a fold at frame 80; then the fold
changes (a 60 degree fold for the 100 degree one).  In one process (``time.process_time``,
one BLAS thread advised: OMP_NUM_THREADS=1): the first run; the whole shot solved again
with the new fold; ``--resume FIRST --from-frame 60`` with the new fold.  Each is the
command line's ``solve`` (:func:`casadi_keyframe.runs.run_solve`), build included, pictures
left out.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/resolve_from_frame.py [--guess aim|none]
        [--from-frame 60] [--rows 12]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from casadi_keyframe.loading import check_overrides, load_module
from casadi_keyframe.runs import run_solve, solve_run
from casadi_keyframe.export.obj import write_obj
from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, write_sheet_and_targets


def solve(folder: Path, fold_file: str, out: str, guess: str, resume=None,
          from_frame=None) -> tuple[float, int]:
    """The command line's ``solve`` of the sheet onto the wave at 40 and ``fold_file`` at
    80 (its build, start, search and result files; no pictures, which cost the same either
    way): ``(CPU seconds, exit code)``, its output kept quiet."""
    overrides = {"cloth": str(folder / "sheet.obj"), "pins": (0, 11), "guess": guess,
                 "keyframes": f"40:{folder / 'wave.obj'},80:{folder / fold_file}"}
    (folder / out).mkdir()
    start = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        module = load_module("mesh_keyframes")
        spec = solve_run(module, "mesh_keyframes", check_overrides(module, overrides),
                         folder / out, resume=resume, from_frame=from_frame, quiet=True,
                         pictures=False, viewer=False)
        code = run_solve(spec)
    return time.process_time() - start, code


def misses(folder: Path, out: str) -> str:
    """A run's status, each keyframe's rms miss (the tolerance is 10 mm) and iterations."""
    summary = json.loads((folder / out / "summary.json").read_text())
    rows = [f"{m['term']}: rms {m['rms_position_error'] * 1e3:.3g} mm"
            for m in summary["breakdown"]["misses"]]
    return f"{summary['status_name']} ({'; '.join(rows)}), {summary['nit']} iterations"


def main_(guess: str, frame: int, rows: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_sheet_and_targets(folder, rows, rows)
        vertices, quads = hanging_sheet(rows, rows)
        write_obj(folder / "fold60.obj", fold(vertices, angle=60.0), quads)
        first, code1 = solve(folder, "fold.obj", "first", guess)
        whole, code2 = solve(folder, "fold60.obj", "whole", guess)
        again, code3 = solve(folder, "fold60.obj", "again", guess, folder / "first", frame)
        a, b = (np.load(folder / name / "result.npz") for name in ("first", "again"))
        kept = (np.array_equal(a["x"][:frame + 1], b["x"][:frame + 1])
                and np.array_equal(a["v"][:frame + 1], b["v"][:frame + 1]))
        print(f"{rows} x {rows} sheet, 80 frames, guess={guess}, --from-frame {frame}")
        print(f"  first run (fold 100 deg):       {first:7.2f} s CPU, exit {code1}: "
              f"{misses(folder, 'first')}")
        print(f"  whole shot again (fold 60 deg): {whole:7.2f} s CPU, exit {code2}: "
              f"{misses(folder, 'whole')}")
        print(f"  re-solved from frame {frame}:       {again:7.2f} s CPU, exit {code3}: "
              f"{misses(folder, 'again')}")
        print(f"  ratio re-solve / whole shot again: {again / whole:.1%}")
        print(f"  frames 0..{frame} bit-identical to the first run's: {kept}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--guess", default="aim", choices=("aim", "track", "land", "none"))
    parser.add_argument("--from-frame", type=int, default=60)
    parser.add_argument("--rows", type=int, default=12)
    args = parser.parse_args()
    main_(args.guess, args.from_frame, args.rows)
