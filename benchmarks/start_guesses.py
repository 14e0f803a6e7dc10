"""mesh_keyframes' starts, before any search: the tracking controller's guesses with 0 to N
learning runs (``guess=aim``'s runs: each aims the path past each target by the miss the
run before left) on the 12 x 12 sheet and the README's 30 x 30 walkthrough, with and
without the springs' rest band; and the exact adjoint's backward growth at each start.

Per row: keyframe misses (mm rms), largest stretch, effort (rms and peak control
acceleration per particle, m/s^2), the exact gradient's norm and backward growth (the
health watch's), CPU seconds of the guess.

    OMP_NUM_THREADS=1 python benchmarks/start_guesses.py --runs 0,1,2,3 --bands 0,0.05
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from casadi_keyframe.adjoints.adjoint import Adjoint  # noqa: E402
from casadi_keyframe.loading import load_problem  # noqa: E402
from casadi_keyframe.scenes.mesh_cloths import tracking_guess  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from search import effort, misses, stretch, walkthrough  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", default="0,1,2,3", help="learning runs (0: guess=track)")
    parser.add_argument("--bands", default="0,0.05", help="rest_band values")
    parser.add_argument("--sheets", default="mesh12,walkthrough")
    args = parser.parse_args(argv)
    folder = Path(tempfile.gettempdir()) / "casadi_keyframe_walkthrough"
    print(f"{'sheet':12s} {'band':>5s} {'runs':>4s} {'misses mm':>10s} {'stretch':>7s} "
          f"{'acc rms':>7s} {'peak':>7s} {'|grad|':>9s} {'growth':>9s} {'CPU s':>6s}")
    for sheet in args.sheets.split(","):
        overrides = walkthrough(folder) if sheet == "walkthrough" else {}
        for band in map(float, args.bands.split(",")):
            prob = load_problem("mesh_keyframes", **overrides, guess="none", rest_band=band)
            for runs in map(int, args.runs.split(",")):
                t = time.process_time()
                u = tracking_guess(prob, land=False, aim=runs)
                cpu = time.process_time() - t
                b = prob.breakdown(u)
                found = Adjoint().evaluate(prob, u)
                rms, peak = effort(prob, u)
                print(f"{sheet:12s} {band:5.2f} {runs:4d} {misses(b):>10s} {stretch(b):7.3f} "
                      f"{rms:7.1f} {peak:7.1f} {np.linalg.norm(found.gradient):9.2e} "
                      f"{found.growth.growth:9.2e} {cpu:6.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
