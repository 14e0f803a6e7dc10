"""A solve run: a problem file solved into a results folder, as ``casadi-keyframe solve``
and every point of a sweep run it.

A run writes ``checkpoint.npz`` at every iteration, then ``result.npz`` and
``summary.json``, then the pictures, each file whole or not at all (:mod:`..saved`).  SIGINT
and SIGTERM stop the search the same way (:mod:`.interrupts`): the best result is written,
the pictures are skipped (``render`` draws them later) and the exit code names the signal.
A second signal stops at once; the files already written stay whole.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

from .. import progress
from ..interrupts import OutOfTime, check, limited
from ..optimize.deadline import Deadline, now
from ..optimize.outcome import INTERRUPTED
from ..optimize.report import format_effort, format_misses, format_physical
from ..saved import (CHECKPOINT, Checkpoint, check_inputs, check_trajectory, input_record,
                     read_run, save_result)
from ..saved.lock import locked
from ..state import SimulationError
from ..optimize.outcome import LIMIT
from .exits import exit_code, guarded, stopped
from .from_frame import held_start, whole_result
from .outputs import draw, write_outputs
from .report import command_line, hint, left_on_disk, report, typed_sets


@dataclass
class SolveRun:
    """What ``casadi-keyframe solve`` asks for: the built problem, where its file is and the
    overrides it was built with, the output folder, the solve request (``settings``, a
    :class:`~casadi_keyframe.optimize.SolveSettings`, passed whole to ``solve``) and what the
    run writes."""

    problem: object
    out: Path
    problem_file: str
    settings: object
    problem_arg: str = ""  # the problem as typed (a name or a path), for the hints
    overrides: dict = field(default_factory=dict)
    resume: str | None = None
    from_frame: int | None = None  # with resume: keep its motion up to this frame (.from_frame)
    quiet: bool = False
    animation: bool = True
    exports: tuple = ()  # export formats written beside the pictures (see .export)
    viewer: bool = True  # the HTML viewer (skipped with a note when plotly is missing)
    pictures: bool = True  # False: result files only ('render' draws them later)
    u0: object = None  # starting controls instead of the problem's (a sweep's perturbed start)
    started: float = field(default_factory=now)  # when the run began: --time-limit counts
    typed: tuple = ()  # the options as the user typed them, for the lines to type again
    draw_limit: float | None = None  # seconds the animation may take (None: the default)


def solve_run(module, problem_arg: str, overrides: dict, out=None, *, given=None,
              **options) -> SolveRun:
    """The :class:`SolveRun` of a loaded problem file built with ``overrides`` (checked
    first), writing to ``out`` (default ``results/PROBLEM``): its solve settings made once,
    before the problem is built, from the file's ``SOLVE`` and the values ``given`` (the
    command line's, a sweep point's: :func:`~casadi_keyframe.optimize.settings.settings_from`),
    so ``solve`` and each point of a sweep solve a problem the same way; ``options`` are
    SolveRun's others."""
    from ..loading import build_problem, resolve, solve_defaults
    from ..optimize.settings import settings_from

    settings = settings_from(solve_defaults(module, overrides), given)
    prob = build_problem(module, **overrides)
    return SolveRun(prob, Path(out) if out else Path("results") / prob.name,
                    problem_file=str(resolve(module.__file__).resolve()), settings=settings,
                    problem_arg=str(problem_arg), overrides=overrides, **options)


def run_solve(spec: SolveRun) -> int:
    """Solve, write, draw; return the exit code (see :data:`EXIT_CODES`).  The folder is
    locked while the run writes there (:func:`~casadi_keyframe.saved.lock.locked`: a second
    run into it is refused), and the run says what it does as it goes
    (:mod:`~casadi_keyframe.progress`; ``quiet``: a line per stage)."""
    done = SimpleNamespace(started=False, written=False)
    with locked(spec.out):
        return guarded(lambda caught: _reported(spec, caught, done),
                       lambda signum: f"\n{spec.problem.name}: {stopped(signum)} "
                                      f"{left_on_disk(done, spec)}")


def _reported(spec, caught, done) -> int:
    with progress.reporting(spec.quiet):
        return _solve(spec, caught, done)


def _solve(spec: SolveRun, caught, done) -> int:
    out = spec.out
    deadline = Deadline(spec.started, spec.settings.time_limit)
    held = _held(spec)
    prob, u0, resumed = _start_of(spec, held)
    origin = ("resumed" if resumed else "given" if u0 is not None
              else "guess" if prob.has_guess else "passive")
    start_controls = prob.initial_controls() if u0 is None else u0
    try:
        with limited(deadline), progress.task(f"{prob.name}: the start ({origin})"):
            start_trajectory = prob.simulate(start_controls, records=False)
        start = (prob.breakdown(start_controls, start_trajectory) if held is None else
                 held.breakdown(start_controls, start_trajectory))  # the whole shot's
    except SimulationError as err:
        raise SimulationError(f"{prob.name}: the simulation fails at the starting controls "
                              f"({origin}): {err}", err.step) from None
    except OutOfTime:
        print(f"{prob.name}: the time limit ({deadline.limit:g} s, counted from the run's "
              f"start) was reached while simulating the start ({origin}): nothing written; "
              "raise --time-limit")
        return exit_code(LIMIT)
    physical = f"; {format_physical(start['physical'])}" if "physical" in start else ""
    effort = f"; {format_effort(start['effort'])}" if "effort" in start else ""
    print(f"{prob.name}: {prob.size} controls; start ({origin}): objective "
          f"{start['objective']:.6g}; {format_misses(start['misses'])}{physical}{effort}")
    _warn_inside(prob, start.get("physical"))
    meta = {"problem": prob.name, "problem_file": spec.problem_file,
            "overrides": spec.overrides, "method": spec.settings.method,
            "gradient": spec.settings.gradient.name, **input_record(prob)}
    done.started = True
    checkpoint = (Checkpoint if held is None else held.checkpoint)(out / CHECKPOINT, **meta)
    result = _search(spec, prob, u0, checkpoint, resumed=resumed, deadline=deadline,
                     start_run=start_trajectory)
    if held is not None:
        result, prob = whole_result(held, result), spec.problem
        start_trajectory = held.spliced(start_trajectory)
    signum = caught.signum if result.status == INTERRUPTED else None
    extra = {"problem_file": spec.problem_file, **input_record(prob),
             **({"resumed_from": {k: v for k, v in resumed.items() if k != "meta"}}
                if resumed else {})}
    summary = save_result(result, out, problem_name=prob.name, overrides=spec.overrides,
                          **extra)
    done.written = True
    report(result, summary, out)
    if result.status == INTERRUPTED:
        print(f"  {stopped(signum)}: pictures skipped; draw them with 'casadi-keyframe "
              f"render {out}', continue with '{command_line(spec, 'solve')} --out {out} "
              f"--resume {out}'")
    elif not spec.pictures:
        print(f"  pictures not drawn; draw them with 'casadi-keyframe render {out}'")
    else:
        draw(prob, result.trajectory, result, out, animation=spec.animation,
             start=start_trajectory, limit=spec.draw_limit, subtitle=", ".join(typed_sets(spec)))
        print(f"  pictures drawn in {out}/")
        write_outputs(spec, result.trajectory)
    hint(result, spec)
    check()  # a signal after the last safe point still counts
    return exit_code(result.status, signum)


def _warn_inside(prob, physical) -> None:
    """A warning when the cloth begins deeper inside a body than the physical limits allow
    (a body's mesh open or wound inward, the cloth placed in it): no search fixes that."""
    if not physical or physical.get("max_penetration_frame") != 0 or prob.limits is None:
        return
    depth = physical.get("max_penetration", 0.0)
    if depth > prob.limits.depth:
        print(f"  warning: the cloth starts {1e3 * depth:.3g} mm inside a body (the limit is "
              f"{1e3 * prob.limits.depth:.3g} mm): no search can pull it out; check that "
              f"each body is a closed mesh whose faces point out (see the notes above) and "
              f"that the cloth starts outside it", file=sys.stderr)


def _start_of(spec: SolveRun, held) -> tuple:
    """``(problem, u0, resumed)``: the problem searched (the frames after a ``held`` one),
    the controls it starts from (None: its own start) and where they came from."""
    if held is not None:
        return held.problem, held.u0, held.record
    u0, resumed = resume_controls(spec) if spec.resume else (spec.u0, {})
    return spec.problem, u0, resumed


def _held(spec: SolveRun):
    """The shot ``spec`` re-solves from a frame (:func:`.from_frame.held_start`), said in a
    line, or None for a whole-shot solve."""
    if spec.from_frame is None:
        return None
    if not spec.resume:
        raise ValueError(f"--from-frame {spec.from_frame} keeps a run's motion up to that "
                         "frame: give the run with --resume RUN")
    coarse = [flag for flag, asked in (("--continuation", spec.settings.continuation),
                                       ("--resolution", spec.settings.resolutions),
                                       ("--homotopy", spec.settings.homotopy)) if asked]
    if coarse:
        raise ValueError(f"--from-frame solves the frames after {spec.from_frame} at the "
                         f"problem's own dt and mesh, and does not combine with "
                         f"{' or '.join(coarse)}: drop it")
    held = held_start(spec.problem, spec.resume, spec.from_frame)
    print(f"{spec.problem.name}: frames 0..{held.frame} kept from {held.record['path']}; "
          f"frames {held.frame + 1}..{spec.problem.steps} solved again, from "
          f"{held.record['start']}")
    return held


def _search(spec: SolveRun, prob, u0, checkpoint, resumed: dict | None = None, *,
            deadline=None, start_run=None):
    """The search ``spec`` asks for on ``prob`` (its problem, or the frames after a held
    one) from ``u0`` (whose run is ``start_run``) until the run's ``deadline``, its settings
    passed whole; a resumed one goes on from its checkpoint's metadata (the problem's own
    mesh, the rounds' round and multipliers)."""
    from ..optimize.search import solve

    return solve(prob, spec.settings, u0=u0, quiet=spec.quiet, checkpoint=checkpoint,
                 resume=resumed.get("meta") if resumed else None, deadline=deadline,
                 start_run=start_run)


def resume_controls(spec: SolveRun):
    """The controls to start from and where they came from, read from ``spec.resume`` (a
    results folder: the newer of its checkpoint and result; or either file).  Refused
    (ValueError) if they were found for another problem, other overrides or another size."""
    run = read_run(spec.resume)
    meta, prob, path = run["meta"], spec.problem, run["path"]
    given = json.loads(json.dumps(spec.overrides, default=str))
    if meta.get("problem") != prob.name:
        raise ValueError(f"--resume {path} holds a run of problem {meta.get('problem')!r}, "
                         f"not {prob.name!r}")
    if meta.get("overrides", {}) != given:
        raise ValueError(f"--resume {path} was solved with overrides {meta.get('overrides')}, "
                         f"this run has {given}: give the same --set values")
    if run["u"].size != prob.size:
        raise ValueError(f"--resume {path} holds {run['u'].size} controls, {prob.name} has "
                         f"{prob.size}")
    check_trajectory(run, prob)  # a stored trajectory that does not fit: an altered file
    check_inputs(meta, path, prob.inputs)
    return run["u"], {"path": str(path), "nit": meta.get("nit"), "fun": meta.get("fun"),
                      "meta": meta}


