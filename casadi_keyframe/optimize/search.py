"""One optimisation of a problem's controls: :func:`solve`.

It takes the request whole (:class:`~.settings.SolveSettings`), checks what depends on the
problem before any simulation, goes through the stages (:mod:`.stages`) coarse to fine, or
the rounds of hard keyframes (:mod:`.rounds`) each through those stages, runs the method of
:data:`~.methods.METHODS` on each through an :class:`~.evaluator.Evaluator`, ends with the
finish if asked (:mod:`.finish`), and returns a :class:`~.result.Result` in scipy's
vocabulary (``status`` included, see :mod:`.outcome`).  Ctrl-C (or any
:class:`~casadi_keyframe.interrupts.Interrupted`) stops the solve and returns the best
controls seen so far with status 3; the time limit stops it with status 1 (one
:class:`~.deadline.Deadline` for the whole call); with ``checkpoint=`` the best is also on
disk after every iteration, written atomically.
"""
from __future__ import annotations

import contextlib
import signal
from dataclasses import replace

import numpy as np

from .. import progress
from ..health import GradientError
from ..interrupts import NAMES, OutOfTime, handled, limited
from ..saved import as_checkpoint
from ..state import SimulationError
from .deadline import Deadline, now
from .evaluator import Evaluator, MetricView
from .finish import check_finish, run_finish
from .goal import GoalReached, check_stop
from .kept import Kept, conclude, evaluate_final, kept_outcome
from .methods import SearchCall, get_method
from .metrics import search_metric
from .outcome import CONVERGED, INTERRUPTED, LIMIT, judge
from .report import format_stage, typed
from .result import Result, assemble, skipped_stage, stage_record
from .rounds import Rounds, run_rounds
from .settings import SolveSettings, as_settings
from .shooting import run_shooting
from .stages import carry, stage_name, stage_overrides, stage_problems


def solve(problem, settings: SolveSettings | str | None = None, *, u0=None,
          quiet: bool = False, checkpoint=None, goal=None, resume: dict | None = None,
          deadline: Deadline | None = None, start_run=None, **keywords) -> Result:
    """Optimise the problem's controls as ``settings`` (a
    :class:`~.settings.SolveSettings`, or a method's name) ask, ``keywords`` (its fields, in
    their loose forms: ``maxiter=100``, ``method="ipopt"``, ``finish="effort"``...) over
    them; a :class:`~.result.Result` (scipy's vocabulary).

    ``u0``: the start (default the problem's guess, else passive); ``quiet``: no progress
    shown (a run that shows its own, as the command line does, shows it here too);
    ``checkpoint``: a ``.npz`` path or Checkpoint that always holds the best point judged so
    far; ``goal``: the problem that judges (default ``problem``); ``resume``: a checkpoint's
    metadata, to go on from (the rounds from their round and multipliers, the problem's own
    mesh straight away); ``deadline``: a :class:`~.deadline.Deadline` begun earlier (a
    command's start; default: ``settings.time_limit`` from now); ``start_run``: the
    simulation of the start, where the caller has it (the result if no evaluation ends in
    time).  The result is never worse than the start, by the goal first and then the
    objective.  Each setting and stage in full: ``docs/explanations/solving.md``.
    """
    settings = as_settings(settings, **keywords)
    stop = check_stop(settings.stop if settings.stop is not None
                      else get_method(settings.method).stop, goal or problem)
    if settings.finish is not None:
        check_finish(problem, settings.finish)
    checkpoint = as_checkpoint(checkpoint)
    deadline = deadline or Deadline.start(settings.time_limit)
    shown = progress.reporting() if not quiet else contextlib.nullcontext()
    with shown:
        if settings.rounds is not None:
            inner = replace(settings, rounds=None)
            return run_rounds(problem, settings.rounds,
                              lambda aimed, u, at: run_stages(
                                  aimed, inner, _Search(inner, at, deadline, stop),
                                  u, goal=problem),
                              u0=u0, resume=resume, checkpoint=checkpoint, deadline=deadline,
                              stop=stop)
        search = _Search(settings, checkpoint, deadline, stop, start_run)
        result = run_stages(problem, settings, search, u0, goal=goal, resumed=bool(resume))
        if settings.finish is None:
            return result
        return run_finish(problem, result, settings.finish, search.kept, deadline)


def solve_augmented(problem, *, rounds: int = 4, weight_growth: float = 1.0,
                    multipliers: bool = True, **options) -> Result:
    """:func:`solve` with ``rounds`` rounds of hard keyframes (:class:`~.rounds.Rounds`:
    each round's keyframes aim past their targets by the multipliers' shifts, their weights
    times ``weight_growth ** round``; ``multipliers=False``: the penalty schedule alone);
    ``options`` as :func:`solve` takes them, ``maxiter`` per round."""
    return solve(problem, rounds=Rounds(rounds, weight_growth, multipliers), **options)


def run_stages(problem, settings: SolveSettings, search, u0=None, *, goal=None,
               resumed: bool = False) -> Result:
    """The solve of ``problem`` through its stages (coarser meshes, homotopy levels, coarser
    time steps, each with multiple shooting if asked; a ``resumed`` run goes straight to the
    problem's own mesh) from ``u0``, judged by ``goal`` (default ``problem``); ``search``
    (:class:`_Search`) is what they share, its kept point the best seen on ``problem``.

    A stage before the last may use half the time the deadline leaves; a start that meets
    the goal (``stop="goal"``) skips the stages before the last and multiple shooting; a
    stage whose best, carried to the problem, is worse there than the best point so far
    hands that point on instead; a stage not run (the time, a signal, nothing to do) is
    recorded as such (:func:`~.result.skipped_stage`)."""
    coarse = []  # meshes left out: no coarser than the problem
    problems = stage_problems(problem, settings.continuation,
                              None if resumed else settings.resolutions, settings.homotopy,
                              coarser_only=settings.coarser_only, skipped=coarse)
    multiple, strategy, stop = settings.shooting, settings.gradient, search.stop
    start = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    kept = search.kept = Kept(problem, goal or problem, search.checkpoint)
    skipped = list(coarse)  # (stage, why): nothing to do there
    if len(problems) > 1 or multiple is not None:  # stages that may end worse than the start
        kept.offer(start, "its start", trajectory=search.start_run)
        if stop == "goal" and kept.standing is not None and kept.standing.met:
            skipped += _nothing_to_do(problems, multiple)
            problems, multiple = problems[-1:], None
    u, handed = (None if u0 is None else carry(problem, start, problems[0])), None
    stages = _said([skipped_stage(p, n, why, CONVERGED, **_made(p, problem))
                    for n, (p, why) in enumerate(skipped)])
    for k, p in enumerate(problems):
        final = p is problem
        export = lambda v, p=p: carry(p, v, problem)  # noqa: E731
        ev = Evaluator(p, strategy, search.checkpoint, stage=len(stages), export=export,
                       goal=(goal or problem) if final else p, stop=stop, final=final,
                       ranks=get_method(settings.method).ranks)
        begin, polish = p.initial_controls() if u is None else u, True
        origin = ("the start" if k == 0 or not stages else handed
                  or f"stage {stages[-1]['stage']}'s best, carried here")
        limit = search.deadline if final else search.deadline.share(0.5)
        if multiple is not None:
            begin, ev, polish = _shoot(p, k, multiple, begin, search, stages, ev, problem,
                                       limit)
            origin = "multiple shooting's result"
        if polish:
            ev.stage = len(stages)
            stages.append(search.run(ev.problem, ev, begin, (k, len(problems)), origin,
                                     limit=limit, **_made(p, problem)))
        if final or stages[-1]["status"] == INTERRUPTED or search.deadline.passed():
            stages += _said(_not_run(problems[k + 1:], stages, search, problem))
            break
        u, handed = _hand_on(p, ev.best_u, kept, problems[k + 1], problem,
                             stages[-1]["stage"], len(search.history))
    ran = [st for st in stages if "skipped" not in st]
    return _result(problem, p, ev, strategy, search, stages, kept, ran[-1], start)


def _hand_on(p, best, kept, following, problem, stage: int, nit: int):
    """``(controls, what they are)`` the stage after stage ``stage`` (on ``p``, its best
    ``best``) starts from, on ``following``: its best carried there (offered to ``kept``
    first), or, where that is worse on ``problem`` than the point ``kept`` holds (and
    ``following`` has the problem's particles) or there is none, the kept point."""
    if best is None:  # its first evaluation did not end in its share of the time
        if kept.u is None:
            return None, None
        return carry(problem, kept.u, following), f"{kept.where}, carried here"
    better = kept.offer(carry(p, best, problem), f"stage {stage}'s best", stage=stage,
                        nit=nit)
    if not better and kept.u is not None and following.model.n == problem.model.n:
        return (carry(problem, kept.u, following),
                f"{kept.where} (stage {stage}'s best is worse on the problem)")
    return carry(p, best, following), None


def _nothing_to_do(problems, multiple) -> list:
    """``(stage, why)`` of the stages before the last (and multiple shooting) that a start
    meeting the goal leaves with nothing to do."""
    why = "nothing to do: the start already meets the goal (stop='goal')"
    return ([(p, why) for p in problems[:-1]]
            + ([(problems[-1], f"multiple shooting: {why}")] if multiple else []))


def _not_run(problems, stages, search, problem) -> list:
    """The records of the stages ``problems`` that the time limit or a signal left unrun."""
    if not problems:
        return []
    interrupted = stages[-1]["status"] == INTERRUPTED
    why = ("interrupted before it began" if interrupted else
           f"the time limit ({search.deadline.limit:g} s) was reached before it began")
    first = stages[-1]["stage"] + 1
    return [skipped_stage(p, first + i, why, INTERRUPTED if interrupted else LIMIT,
                          **_made(p, problem))
            for i, p in enumerate(problems)]


def _said(records: list) -> list:
    """``records`` (stages not run), each said as a stage line as it is decided."""
    for record in records:
        progress.say("  " + format_stage(record), stage=True)
    return records


def _made(stage, problem) -> dict:
    """A stage record's ``overrides`` key, where its problem has any of its own."""
    made = stage_overrides(stage, problem)
    return {"overrides": made} if made else {}


def _shoot(p, k, opts, start, search, stages, ev, origin, limit):
    """Stage ``k``'s multiple shooting (its record appended to ``stages``) within ``limit``
    (the stage's :class:`~.deadline.Deadline`): ``(controls, evaluator, polish?)``.  The
    polish searches the problem whose keyframes aim where the shooting's multipliers left
    them (judged by the true targets); without a polish, or after an interrupt or the time
    limit, the shooting's controls are evaluated and judged as they are."""
    opts = opts if k == 0 else replace(opts, init="guess")
    record, start, aimed = run_shooting(p, opts, start, search, len(stages), ev.goal,
                                        ev.export, origin, limit)
    stages.append(record)
    progress.say("  " + format_stage(record), stage=True)
    if opts.polish and record["status"] != INTERRUPTED and not limit.passed():
        if aimed is not p:
            ev = Evaluator(aimed, ev.gradient, ev.checkpoint, stage=len(stages),
                           export=ev.export, goal=ev.goal, stop=ev.stop, final=ev.final,
                           ranks=ev.ranks)
        return start, ev, True
    evaluate_at(ev, start, exact=record["status"] != INTERRUPTED and not limit.passed())
    record["status"], record["message"] = judge(record["status"], record["message"],
                                                ev.verdict())
    record["success"] = record["status"] == CONVERGED
    return start, ev, False


def evaluate_at(ev, u, *, exact: bool = True) -> None:
    """Evaluate ``ev`` at the controls ``u`` (its best point then); after an interrupt or
    the time limit (``exact`` False), or one during it, the objective alone."""
    try:
        if exact:
            ev(u)
            return
    except KeyboardInterrupt:
        handled()
    f = ev.problem.objective(u)
    ev.best_u, ev.best_f, ev.best_g = u, f, np.full(u.size, np.nan)


def _result(problem, p, ev, strategy, search, stages, kept, last, start) -> Result:
    """The Result at ``problem.dt`` from the evaluator ``ev`` of the last stage run (``p``,
    its record ``last``), or the ``kept`` point where that ended worse or evaluated
    nothing (the ``start`` if nothing was kept); after a signal or the time limit no gradient is computed that the search did
    not (it is NaN)."""
    status, message = last["status"], last["message"]
    late = status == INTERRUPTED or search.deadline.passed()
    if ev.best_u is None:  # not one evaluation ended: the best point so far, or the start
        if kept.u is None:
            kept.offer(start, "its start", trajectory=search.start_run)
        return conclude(problem, kept, strategy, status=status, message=message,
                        stages=stages, history=search.history, method=search.method,
                        started=search.clock.started, gradient=not late)
    if p is problem and ev.problem is problem and ev.best_g is not None:
        u, fun, jac = ev.best_u, float(ev.best_f), ev.best_g
        run = None if ev.best_info is None else ev.best_info.trajectory
        trajectory = problem.simulate(u) if run is None else run
    elif p is problem:  # a polish whose keyframes aimed elsewhere, or a point judged alone
        u = ev.best_u
        fun, jac, trajectory = _final(problem, strategy, u, late)
    else:
        u = carry(p, ev.best_u, problem)
        fun, jac, trajectory = _final(problem, strategy, u, late)
        if status != INTERRUPTED:  # the time limit, maybe reached just as the stage ended
            status = LIMIT
            message = f"time limit reached ({search.deadline.limit:g} s) before converging"
        message = (f"{message}, in stage {last['stage']} ({stage_name(p)}): its best "
                   f"controls, carried to the problem ({stage_name(problem)}), kept")
    if kept.beats(u, trajectory):
        status, message = kept_outcome(kept, status, message)
        return conclude(problem, kept, strategy, status=status, message=message,
                        stages=stages, history=search.history, method=search.method,
                        started=search.clock.started, gradient=not late)
    # the checkpoint holds the result too (a coarse stage's, carried, once judged here)
    kept.offer(u, "the result", trajectory=trajectory, stage=last["stage"],
               nit=len(search.history))
    return assemble(problem, u, fun=fun, jac=jac, status=status, message=message,
                    method=search.method, route=strategy,
                    stages=stages, history=search.history, started=search.clock.started,
                    trajectory=trajectory)


def _final(problem, route, u, late: bool):
    """``(objective, gradient, run)`` of ``problem`` at ``u``: the gradient by ``route``, or
    NaN when the search ended ``late`` (a signal, the time limit: no more work)."""
    if late:
        run = problem.simulate(u, records=False)
        fun = problem.state_cost(run, gradient=False)[0] + problem.control_cost(u)[0]
        return float(fun), np.full(u.size, np.nan), run
    fun, jac = evaluate_final(problem, route, u)
    return fun, jac, problem.simulate(u)


class _Search:
    """What the stages of one run share: the request (``settings``: method, options,
    limits), the history, the checkpoint, the kept point, its own clock (the history's and
    the result's times), the call's one :class:`~.deadline.Deadline` and the start's run
    where the caller had it (``start_run``)."""

    def __init__(self, settings, checkpoint, deadline, stop, start_run=None):
        self.method, self.maxiter = settings.method, settings.maxiter
        self.tol, self.options = settings.tol, settings.options
        self.checkpoint, self.deadline, self.stop = checkpoint, deadline, stop
        self.start_run = start_run
        self.history, self.clock, self.kept = [], Deadline.start(), None

    def call(self, maxiter, on_iteration, deadline=None) -> SearchCall:
        """What a run of the method is given: ``maxiter``, the settings' tolerance and
        options, the deadline (the call's, or a stage's share of it), ``on_iteration``."""
        return SearchCall(maxiter, self.tol, self.options, deadline or self.deadline,
                          on_iteration)

    def run(self, problem, ev, u0, stage, origin: str = "the start", *, limit=None,
            overrides=None) -> dict:
        """One method run from ``u0`` (``origin`` says what it is) until ``limit`` (the
        stage's :class:`~.deadline.Deadline`, default the call's): the stage's
        :class:`~.result.Stage` (``overrides``: the build overrides that make its problem,
        where they differ from the solve's), its objective on the stage's true targets;
        its line said (:mod:`~casadi_keyframe.progress`)."""
        limit = limit or self.deadline
        t, first = now(), len(self.history)
        label = _label(problem, self.method, stage, overrides)
        with progress.task(label, self.maxiter, "iterations", limit=limit, exact=False):
            status, message = self._search(problem, ev, u0, stage, origin, limit)
        if status == LIMIT and limit.passed() and ev.best_u is not None:
            message = _out_of_time(limit, self.deadline, "before converging")
        if ev.best_u is not None:
            status, message = judge(status, message, ev.verdict())
            ev.keep(nit=len(self.history))
        record = stage_record(problem, ev.stage, nit=len(self.history) - first,
                              fun=ev.best_objective() if ev.best_u is not None else np.nan,
                              status=status, message=message,
                              seconds=now() - t, start=ev.start or (None, None), **ev.counts(),
                              **ev.health.stage_fields(),
                              **({"overrides": overrides} if overrides else {}))
        progress.say("  " + format_stage(record), stage=True)
        return record

    def _search(self, problem, ev, u0, stage, origin, limit):
        k, count = stage
        where = "" if count == 1 else f" of stage {ev.stage} ({stage_name(problem)})"
        try:
            with limited(limit):
                f0, _ = ev(u0)
        except OutOfTime:
            return LIMIT, _out_of_time(limit, self.deadline, f"during the first evaluation"
                                                             f"{where}; its start is kept")
        except KeyboardInterrupt as err:
            handled()
            return INTERRUPTED, (f"interrupted {_who(err)} during the first evaluation{where}; "
                                 "its start is kept")
        ev.start = (float(f0), float(f0 - problem.control_cost(u0)[0]))
        if isinstance(ev.last_error, GradientError):
            raise ev.last_error  # the route's own message says what to use instead
        if ev.failures:
            raise SimulationError(f"the simulation fails at the starting controls{where} "
                                  f"({ev.last_failure})"
                                  + ("" if not where else "; start the continuation at a "
                                     "finer dt or mesh" if k == 0 else "; the controls "
                                     "carried from the previous stage fail here: start the "
                                     "continuation at a finer dt or mesh"), 0)
        ev.keep(nit=len(self.history))
        try:
            ev.check_goal(0)
        except GoalReached:
            return CONVERGED, f"converged: {origin} already meets the goal (stop='goal')"
        run = get_method(self.method).run
        metric = search_metric(problem)
        searched, start = (ev, u0) if metric is None else (MetricView(ev, metric),
                                                          metric.unsmooth(u0))
        before = len(self.history)
        try:
            with limited(limit):
                return run(problem, searched, start,
                           self.call(self.maxiter, lambda: ev.record(self.history, self.clock),
                                     limit))
        except GoalReached as reached:
            here = "" if count == 1 else f", {reached.iteration - before} in this stage"
            return CONVERGED, (f"converged: the goal is met at iteration {reached.iteration}"
                               f"{here} (stop='goal')")
        except OutOfTime:
            return LIMIT, "time limit reached before converging"
        except KeyboardInterrupt as err:
            handled()
            return INTERRUPTED, f"interrupted {_who(err)}; best result kept"


def _who(err) -> str:
    """``"by user (SIGINT)"`` or ``"by SIGTERM"``: what a KeyboardInterrupt came from."""
    signum = getattr(err, "signum", signal.SIGINT)
    return "by user (SIGINT)" if signum == signal.SIGINT else f"by {NAMES.get(signum, signum)}"


def _out_of_time(limit, deadline, when: str) -> str:
    """``"time limit reached (40 s) before converging"``, or, for a stage stopped at its
    share of the time, ``"its share of the time limit (12.3 s of 40 s) used ..."``."""
    if limit is deadline or deadline.passed():
        return f"time limit reached ({deadline.limit:g} s) {when}"
    return (f"its share of the time limit used ({limit.limit:.3g} s of the {deadline.limit:g} "
            f"s), left to the stages after it, {when}")


def _label(problem, method, stage, overrides) -> str:
    """A stage's progress label: ``"cape_blend [lbfgsb] stage 0/1 (contact=3)"``."""
    k, count = stage
    said = ", ".join(f"{key}={typed(value)}" for key, value in (overrides or {}).items())
    return (f"{problem.name} [{method}]" + ("" if count == 1 else f" stage {k}/{count - 1}")
            + (f" ({said})" if said else ""))
