"""One run of the formulations study (:mod:`.formulations`) in a process of its own, so that
its peak memory is its own: the problem file solved through the command line's own path
(:func:`~casadi_keyframe.runs.solve_run`, :func:`~casadi_keyframe.runs.run_solve`: the
file's ``SOLVE`` under what the run asks for), its result written into the run's folder, and
beside it ``measured.json``: the exit code, the CPU seconds of the solve
(``time.process_time``), the process's peak resident memory after the build and at the end
(``ru_maxrss``), and the settings the solve ran with.

    python -m casadi_keyframe.studies.formulation_run SPEC.json

``SPEC.json``: ``{"problem", "overrides", "given", "out"}`` (``given``: the solve request's
values, as ``--method``, ``--gradient``, ``--option``, ``--segments``, ``--maxiter`` and
``--time-limit`` give them).
"""
from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

MEASURED = "measured.json"


def peak_mb() -> float:
    """This process's peak resident memory so far (MB; Linux reports ``ru_maxrss`` in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run(spec: dict) -> dict:
    """Solve ``spec``'s problem as ``casadi-keyframe solve`` does, into ``spec["out"]``; what
    was measured (also written to its ``measured.json``)."""
    from ..loading import load_module
    from ..runs import run_solve, solve_run
    from ..saved.files import write_json

    out = Path(spec["out"])
    module = load_module(spec["problem"])
    request = solve_run(module, spec["problem"], spec["overrides"], out, given=spec["given"],
                        quiet=True, pictures=False, animation=False, viewer=False)
    built = peak_mb()
    started = time.process_time()
    code = run_solve(request)
    measured = {"exit": code, "cpu_seconds": time.process_time() - started,
                "built_mb": built, "peak_mb": peak_mb(),
                "settings": request.settings.describe()}
    write_json(out / MEASURED, measured)
    return measured


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    run(json.loads(Path(args[0]).read_text()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
