"""Run a solve as a command and leave its outputs on disk (``casadi-keyframe solve`` and
``render``).

A run writes ``checkpoint.npz`` at every iteration, then ``result.npz`` and
``summary.json``, then the pictures, each file whole or not at all (:mod:`.io`).  SIGINT
and SIGTERM stop the search the same way (:mod:`.interrupts`): the best result is written,
the pictures are skipped (``render`` draws them later) and the exit code names the signal.
A second signal stops at once; the files already written stay whole.
"""
from __future__ import annotations

import json
import signal
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

from .interrupts import NAMES, catching, check
from .saved import CHECKPOINT, RESULT, Checkpoint, read_run, save_result
from .optimize.outcome import CONVERGED, FAILED, INTERRUPTED, LIMIT
from .report import format_misses, format_physical, format_stage, set_value
from .saved import check_trajectory
from .state import SimulationError

EXIT_CODES = """\
exit codes:
  0    converged: every keyframe within its tolerance; result and pictures written
  1    the search failed: the method stopped short of the goal (line search, no further
       decrease, IPOPT error...), the keyframes missed named, the best point still
       written; or the simulation fails at the start (nothing written)
  2    bad input (problem, overrides, options, --resume source)
  3    stopped at --maxiter or --time-limit before converging; result written: raise the
       limit or continue with --resume OUT
  130  interrupted by Ctrl-C (SIGINT); result written, pictures skipped ('render OUT')
  143  stopped by SIGTERM; as 130"""
_EXIT = {CONVERGED: 0, FAILED: 1, LIMIT: 3}
_SIGNAL_EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143}


def exit_code(status: int, signum: int | None = None) -> int:
    """The command's exit code for a result ``status`` (and the signal that stopped it)."""
    if status == INTERRUPTED:
        return _SIGNAL_EXIT.get(signum or signal.SIGINT, 128 + (signum or 2))
    return _EXIT[status]


@dataclass
class SolveRun:
    """What ``casadi-keyframe solve`` asks for: the built problem, where its file is and the
    overrides it was built with, the output folder and the search's options."""

    problem: object
    out: Path
    problem_file: str
    problem_arg: str = ""  # the problem as typed (a name or a path), for the hints
    overrides: dict = field(default_factory=dict)
    method: str = "lbfgsb"
    gradient: str = "adjoint"
    maxiter: int = 200
    continuation: list | None = None
    resolutions: list = field(default_factory=list)  # build overrides of coarser meshes
    rounds: dict = field(default_factory=dict)  # rounds, weight_growth for solve_augmented
    shooting: dict | None = None  # multiple shooting's options (solve's shooting=)
    homotopy: list | None = None  # build overrides of the homotopy's levels (solve's homotopy=)
    time_limit: float | None = None
    stop: str | None = None  # "goal", "method" or None (the goal where tolerances exist)
    resume: str | None = None
    quiet: bool = False
    animation: bool = True
    exports: tuple = ()  # export formats written beside the pictures (see .export)
    viewer: bool = True  # the HTML viewer (skipped with a note when plotly is missing)
    pictures: bool = True  # False: result files only ('render' draws them later)
    u0: object = None  # starting controls instead of the problem's (a sweep's perturbed start)


def solve_run(module, problem_arg: str, overrides: dict, out=None, *, method=None,
              gradient=None, maxiter=None, rounds=None, weight_growth=None,
              resolutions=None, shooting=None, **options) -> SolveRun:
    """The :class:`SolveRun` of a loaded problem file built with ``overrides`` (checked
    first), writing to ``out`` (default ``results/PROBLEM``): the search options not given
    (None) come from the file's ``SOLVE`` (:func:`.loading.solve_defaults`), so ``solve`` and
    each point of a sweep solve a problem the same way; ``options`` are SolveRun's others.
    The file's default ``resolutions`` keep only the meshes coarser than the problem built
    (none when it is built coarse itself), and give way to rounds asked for; rounds and
    resolutions both given are refused (ValueError).  ``shooting`` (options of multiple
    shooting, ``{"segments": 0}`` for none) goes over the file's."""
    from .loading import build_problem, default_resolutions, resolve, solve_defaults

    prob = build_problem(module, **overrides)
    defaults = solve_defaults(module, overrides)
    shooting = {**defaults.get("shooting", {}), **(shooting or {})} or None
    if options.get("homotopy") is None and defaults.get("homotopy"):
        options["homotopy"] = [dict(h) for h in defaults["homotopy"]]
    if shooting and shooting.get("segments", 1) <= 1:
        shooting = None
    given = {k: v for k, v in (("rounds", rounds), ("weight_growth", weight_growth))
             if v is not None}
    if given and resolutions:
        raise ValueError("coarse meshes (--resolution) and augmented-Lagrangian rounds "
                         "(--rounds, --weight-growth) do not combine: choose one")
    rounds = given or ({} if resolutions else
                       {k: defaults[k] for k in ("rounds", "weight_growth") if k in defaults})
    if resolutions is None:  # the file's, unless rounds are asked for
        resolutions = [] if rounds else default_resolutions(module, prob)
    return SolveRun(
        prob, Path(out) if out else Path("results") / prob.name,
        problem_file=str(resolve(module.__file__).resolve()), problem_arg=str(problem_arg),
        overrides=overrides, method=method or defaults["method"],
        gradient=gradient or defaults["gradient"],
        maxiter=defaults["maxiter"] if maxiter is None else maxiter,
        resolutions=[dict(r) for r in resolutions], rounds=rounds, shooting=shooting,
        **options)


def run_solve(spec: SolveRun) -> int:
    """Solve, write, draw; return the exit code (see :data:`EXIT_CODES`)."""
    done = SimpleNamespace(started=False, written=False)
    return _guarded(lambda caught: _solve(spec, caught, done),
                    lambda signum: f"\n{spec.problem.name}: {_stopped(signum)} "
                                   f"{_where(done, spec)}")


def _guarded(work, stopped) -> int:
    """``work(caught)``'s exit code, or, when SIGINT or SIGTERM stops it, ``stopped(signum)``
    printed and the signal's exit code."""
    with catching() as caught:
        try:
            return work(caught)
        except Exception:  # raised inside C code, a signal can surface as another error
            if caught.signum is None:
                raise
            signum = caught.signum
        except KeyboardInterrupt as err:
            signum = getattr(err, "signum", signal.SIGINT)
        print(stopped(signum))
        return exit_code(INTERRUPTED, signum)


def _solve(spec: SolveRun, caught, done) -> int:
    prob, out = spec.problem, spec.out
    u0, resumed = resume_controls(spec) if spec.resume else (spec.u0, {})
    origin = ("resumed" if resumed else "given" if u0 is not None
              else "guess" if prob.has_guess else "passive")
    start_controls = prob.initial_controls() if u0 is None else u0
    try:
        start_trajectory = prob.simulate(start_controls, records=False)
        start = prob.breakdown(start_controls, start_trajectory)
    except SimulationError as err:
        raise SimulationError(f"{prob.name}: the simulation fails at the starting controls "
                              f"({origin}): {err}", err.step) from None
    physical = f"; {format_physical(start['physical'])}" if "physical" in start else ""
    print(f"{prob.name}: {prob.size} controls; start ({origin}): objective "
          f"{start['objective']:.6g}; {format_misses(start['misses'])}{physical}")
    meta = {"problem": prob.name, "problem_file": spec.problem_file,
            "overrides": spec.overrides, "method": spec.method, "gradient": spec.gradient}
    done.started = True
    result = _search(spec, u0, Checkpoint(out / CHECKPOINT, **meta), resumed=resumed)
    signum = caught.signum if result.status == INTERRUPTED else None
    extra = {"problem_file": spec.problem_file,
             **({"resumed_from": {k: v for k, v in resumed.items() if k != "meta"}}
                if resumed else {})}
    summary = save_result(result, out, problem_name=prob.name, overrides=spec.overrides,
                          **extra)
    done.written = True
    report(result, summary, out)
    if result.status == INTERRUPTED:
        print(f"  {_stopped(signum)}: pictures skipped; draw them with 'casadi-keyframe "
              f"render {out}', continue with '{_command(spec, 'solve')} --out {out} "
              f"--resume {out}'")
    elif not spec.pictures:
        print(f"  pictures not drawn; draw them with 'casadi-keyframe render {out}'")
    else:
        draw(prob, result.trajectory, result, out, animation=spec.animation,
             start=start_trajectory)
        print(f"  pictures drawn in {out}/")
        _write_outputs(spec, result.trajectory)
    _hint(result.status, spec)
    check()  # a signal after the last safe point still counts
    return exit_code(result.status, signum)


def _write_outputs(spec: SolveRun, trajectory) -> None:
    """The viewer and the ``--export`` formats, each file named as it is written."""
    from .export import write_outputs

    paths = write_outputs(spec.problem, trajectory, spec.out, spec.exports, viewer=spec.viewer)
    if paths:
        shown = [str(p) for p in paths[:3]] + ([f"... {len(paths) - 3} more"] if len(paths) > 3 else [])
        print(f"  exported: {', '.join(shown)}")


def run_export(source, formats, *, out=None) -> int:
    """Export a saved run (``casadi-keyframe export``) in each of ``formats``; exit code 0."""
    from .export import check_library, export

    for fmt in formats:  # every format's library before any file is written
        check_library(fmt)
    for fmt in formats:
        paths = export(source, fmt, out=out)
        more = f" ... ({len(paths)} files)" if len(paths) > 2 else ""
        print(f"{fmt}: {', '.join(str(p) for p in paths[:2])}{more}")
    return 0


def _search(spec: SolveRun, u0, checkpoint, resumed: dict | None = None):
    """The search ``spec`` asks for from ``u0``; a resumed one goes straight to the problem's
    own mesh (its controls were found there), and rounds go on from the round and the
    multipliers its checkpoint carries."""
    from .optimize import solve

    options = dict(method=spec.method, gradient=spec.gradient, maxiter=spec.maxiter,
                   quiet=spec.quiet, checkpoint=checkpoint, continuation=spec.continuation,
                   time_limit=spec.time_limit, u0=u0, stop=spec.stop, shooting=spec.shooting,
                   homotopy=spec.homotopy)
    if spec.rounds:
        from .optimize.augmented_lagrangian import solve_augmented
        return solve_augmented(spec.problem, **spec.rounds, **options,
                               resume=resumed.get("meta") if resumed else None)
    resolutions = None if resumed or not spec.resolutions else spec.resolutions
    return solve(spec.problem, resolutions=resolutions, **options)


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
    return run["u"], {"path": str(path), "nit": meta.get("nit"), "fun": meta.get("fun"),
                      "meta": meta}


def report(result, summary, out) -> None:
    """Print the outcome: message, totals, each stage or round, the keyframe misses."""
    print(f"{summary['problem']}: {result.message}")
    print(f"  objective {summary['fun']:.6g}  iterations {result.nit}  evaluations "
          f"{result.nfev}  wall {result.timings['wall_seconds']:.1f} s")
    if len(result.stages) > 1:
        for st in result.stages:
            print("  " + format_stage(st))
    for miss in summary["breakdown"]["misses"]:
        print(f"  {format_misses([miss])}")
    if "physical" in summary["breakdown"]:
        print(f"  {format_physical(summary['breakdown']['physical'])}")
    print(f"  result written to {out}/{RESULT} and summary.json")


def _hint(status: int, spec: SolveRun) -> None:
    if status == LIMIT:
        print(f"  hint: raise --maxiter or --time-limit, or continue from this result:\n"
              f"    {_command(spec, 'solve')} --out {spec.out} --resume {spec.out}")
    elif status == FAILED:
        print(f"  hint: '{_command(spec, 'gradcheck')}' compares the gradient routes; "
              "--gradient casadi uses CasADi's reverse mode (small systems)")


def _command(spec: SolveRun, command: str) -> str:
    """``casadi-keyframe COMMAND PROBLEM --set ...`` for this run's problem and overrides (and,
    for ``solve``, its method and gradient route, so a resumed run goes on the same way)."""
    sets = "".join(f" --set {k}={set_value(v)}" for k, v in spec.overrides.items())
    if command == "solve":
        sets += f" --method {spec.method} --gradient {spec.gradient}"
    return f"casadi-keyframe {command} {spec.problem_arg or spec.problem_file}{sets}"


def _stopped(signum) -> str:
    signum = signum or signal.SIGINT
    return "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"stopped by {NAMES.get(signum, signum)}"


def _where(done, spec: SolveRun) -> str:
    """What a second interrupt leaves on disk."""
    out = spec.out
    if done.written:
        return (f"while drawing: the result is in {out}/{RESULT}; draw the pictures with "
                f"'casadi-keyframe render {out}'")
    if done.started and (Path(out) / CHECKPOINT).is_file():
        return (f"before the result was written: the best controls so far are in "
                f"{out}/{CHECKPOINT}; draw them with 'casadi-keyframe render {out}' or "
                f"continue with '{_command(spec, 'solve')} --out {out} --resume {out}'")
    return "before the first iteration: nothing new written"


def draw(problem, trajectory, result, out, *, animation: bool = True, start=None) -> None:
    """convergence.png (if ``result`` has a history), keyframes.png, animation.gif and, given
    the ``start`` trajectory of a cloth's search, start_and_result.png (the two side by
    side)."""
    from . import render

    out = Path(out)
    if getattr(result, "history", None):
        render.convergence(result, out / "convergence.png")
    render.snapshot(problem, trajectory, out / "keyframes.png")
    if start is not None and render.renderer(problem) is render.cloth:
        render.cloth.side_by_side(problem, {"start": start, "result": trajectory},
                                  out / "start_and_result.png")
    if animation:
        render.animate(problem, trajectory, out / "animation.gif")


def run_render(source, *, animation: bool = True) -> int:
    """Draw a saved run's pictures again (``casadi-keyframe render``); the exit code."""
    def work(caught):
        code = _render(source, animation)
        check()
        return code

    return _guarded(work, lambda signum: f"\n{_stopped(signum)}: drawing stopped; the "
                                         "pictures drawn so far are whole")


def _render(source, animation: bool) -> int:
    from .saved import writable_folder
    from .saved import load_saved, saved_file

    path = saved_file(source)
    writable_folder(path.parent, "the results folder", fix="render draws beside the run "
                    "file: copy the folder somewhere you can write and render the copy")
    saved = load_saved(path)
    prob, out = saved.problem, saved.path.parent
    draw(prob, saved.trajectory, _history(saved.meta, saved.arrays), out, animation=animation)
    print(f"{prob.name}: pictures drawn in {out}/ from {saved.path.name}")
    return 0


def _history(meta, arrays) -> SimpleNamespace:
    """What :func:`render.convergence` reads, from a result.npz's arrays."""
    objective = arrays.get("history_objective", ())
    history = [{"iteration": i + 1, "objective": float(f),
                "keyframe_error": float(arrays["history_keyframe_error"][i]),
                "seconds": float(arrays["history_seconds"][i]),
                **{key: cast(arrays[f"history_{key}"][i])
                   for key, cast in (("stage", int), ("dt", float), ("particles", int),
                                     ("round", int))
                   if f"history_{key}" in arrays},  # older files lack some
                } for i, f in enumerate(objective)]
    for record in history:
        if record.get("round", 0) < 0:  # written as -1: no rounds
            del record["round"]
    start = {k: float(arrays[f"start_{k}"]) if f"start_{k}" in arrays else None
             for k in ("objective", "keyframe_error")}
    return SimpleNamespace(history=history, start=start, method=meta.get("method", "?"),
                           gradient=meta.get("gradient", "?"))
