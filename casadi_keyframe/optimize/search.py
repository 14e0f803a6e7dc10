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

import signal
from dataclasses import replace

import numpy as np

from tqdm.auto import tqdm

from ..health import GradientError
from ..interrupts import NAMES, handled
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
from .result import Result, assemble, stage_record
from .rounds import Rounds, run_rounds
from .settings import SolveSettings, as_settings
from .shooting import run_shooting
from .stages import carry, stage_name, stage_problems


def solve(problem, settings: SolveSettings | str | None = None, *, u0=None,
          quiet: bool = False, checkpoint=None, goal=None, resume: dict | None = None,
          **keywords) -> Result:
    """Optimise the problem's controls as ``settings`` (a
    :class:`~.settings.SolveSettings`, or a method's name) ask, ``keywords`` (its fields, in
    their loose forms: ``maxiter=100``, ``method="ipopt"``, ``finish="effort"``...) over
    them; a :class:`~.result.Result` (scipy's vocabulary).

    ``u0``: the start (default the problem's guess, else passive); ``quiet``: no progress
    bar; ``checkpoint``: a ``.npz`` path or Checkpoint that always holds the best point
    judged so far; ``goal``: the problem that judges (default ``problem``); ``resume``: a
    checkpoint's metadata, to go on from (the rounds from their round and multipliers, the
    problem's own mesh straight away).  The result is never worse than the start, by the
    goal first and then the objective.  Each setting and stage in full:
    ``docs/explanations/solving.md``.
    """
    settings = as_settings(settings, **keywords)
    stop = check_stop(settings.stop if settings.stop is not None
                      else get_method(settings.method).stop, goal or problem)
    if settings.finish is not None:
        check_finish(problem, settings.finish)
    checkpoint, deadline = as_checkpoint(checkpoint), Deadline.start(settings.time_limit)
    if settings.rounds is not None:
        inner = replace(settings, rounds=None)
        return run_rounds(problem, settings.rounds,
                          lambda aimed, u, at: run_stages(
                              aimed, inner, _Search(inner, quiet, at, deadline, stop), u,
                              goal=problem),
                          u0=u0, resume=resume, checkpoint=checkpoint, deadline=deadline,
                          stop=stop)
    search = _Search(settings, quiet, checkpoint, deadline, stop)
    result = run_stages(problem, settings, search, u0, goal=goal, resumed=bool(resume))
    if settings.finish is None or result.status == INTERRUPTED or deadline.passed():
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
    (:class:`_Search`) is what they share, its kept point the best seen on ``problem``."""
    problems = stage_problems(problem, settings.continuation,
                              None if resumed else settings.resolutions, settings.homotopy,
                              coarser_only=settings.coarser_only)
    multiple, strategy, stop = settings.shooting, settings.gradient, search.stop
    start = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    kept = search.kept = Kept(problem, goal or problem, search.checkpoint)
    if len(problems) > 1 or multiple is not None:  # stages that may end worse than the start
        kept.offer(start, "its start")
    u = None if u0 is None else carry(problem, start, problems[0])
    stages = []
    for k, p in enumerate(problems):
        final = p is problem
        export = lambda v, p=p: carry(p, v, problem)  # noqa: E731
        ev = Evaluator(p, strategy, search.checkpoint, stage=len(stages), export=export,
                       goal=(goal or problem) if final else p, stop=stop, final=final,
                       ranks=get_method(settings.method).ranks)
        begin, polish = p.initial_controls() if u is None else u, True
        origin = ("the start" if k == 0 else
                  f"stage {stages[-1]['stage']}'s best, carried here" if stages else "the start")
        if multiple is not None:
            begin, ev, polish = _shoot(p, k, multiple, begin, search, stages, ev, problem)
            origin = "multiple shooting's result"
        if polish:
            ev.stage = len(stages)
            stages.append(search.run(ev.problem, ev, begin, (k, len(problems)), origin))
        if final or stages[-1]["status"] == INTERRUPTED or search.deadline.passed():
            break
        kept.offer(carry(p, ev.best_u, problem), f"stage {stages[-1]['stage']}'s best",
                   stage=stages[-1]["stage"], nit=len(search.history))
        u = carry(p, ev.best_u, problems[k + 1])
    return _result(problem, p, ev, strategy, search, stages, kept)


def _shoot(p, k, opts, start, search, stages, ev, origin):
    """Stage ``k``'s multiple shooting (its record appended to ``stages``): ``(controls,
    evaluator, polish?)``.  The polish searches the problem whose keyframes aim where the
    shooting's multipliers left them (judged by the true targets); without a polish, or
    after an interrupt or the time limit, the shooting's controls are evaluated and judged
    as they are."""
    opts = opts if k == 0 else replace(opts, init="guess")
    record, start, aimed = run_shooting(p, opts, start, search, len(stages), ev.goal,
                                        ev.export, origin)
    stages.append(record)
    if opts.polish and record["status"] != INTERRUPTED and not search.deadline.passed():
        if aimed is not p:
            ev = Evaluator(aimed, ev.gradient, ev.checkpoint, stage=len(stages),
                           export=ev.export, goal=ev.goal, stop=ev.stop, final=ev.final,
                           ranks=ev.ranks)
        return start, ev, True
    evaluate_at(ev, start)
    record["status"], record["message"] = judge(record["status"], record["message"],
                                                ev.verdict())
    record["success"] = record["status"] == CONVERGED
    return start, ev, False


def evaluate_at(ev, u) -> None:
    """Evaluate ``ev`` at the controls ``u`` (its best point then), an interrupt during it
    leaving the objective alone."""
    try:
        ev(u)
    except KeyboardInterrupt:
        handled()
        f = ev.problem.objective(u)
        ev.best_u, ev.best_f, ev.best_g = u, f, np.full(u.size, np.nan)


def _result(problem, p, ev, strategy, search, stages, kept) -> Result:
    """The Result at ``problem.dt`` from the evaluator ``ev`` of the last stage run (``p``),
    or the ``kept`` point where that ended worse."""
    status, message = stages[-1]["status"], stages[-1]["message"]
    if p is problem and ev.problem is problem and ev.best_g is not None:
        u, fun, jac = ev.best_u, float(ev.best_f), ev.best_g
    elif p is problem:  # a polish whose keyframes aimed elsewhere, or a point judged alone
        u = ev.best_u
        fun, jac = evaluate_final(problem, strategy, u)
    else:
        u = carry(p, ev.best_u, problem)
        fun, jac = evaluate_final(problem, strategy, u)
        if status != INTERRUPTED:  # the time limit, maybe reached just as the stage ended
            status = LIMIT
            message = f"time limit reached ({search.deadline.limit:g} s) before converging"
        message = (f"{message}, in stage {stages[-1]['stage']} ({stage_name(p)}): its best "
                   f"controls, carried to the problem ({stage_name(problem)}), kept")
    trajectory = problem.simulate(u)
    if kept.beats(u, trajectory):
        status, message = kept_outcome(kept, status, message)
        return conclude(problem, kept, strategy, status=status, message=message,
                        stages=stages, history=search.history, method=search.method,
                        started=search.clock.started)
    # the checkpoint holds the result too (a coarse stage's, carried, once judged here)
    kept.offer(u, "the result", trajectory=trajectory, stage=stages[-1]["stage"],
               nit=len(search.history))
    return assemble(problem, u, fun=fun, jac=jac, status=status, message=message,
                    method=search.method, route=strategy,
                    stages=stages, history=search.history, started=search.clock.started,
                    trajectory=trajectory)


class _Search:
    """What the stages of one run share: the request (``settings``: method, options,
    limits), the history, the checkpoint, the kept point, its own clock (the history's and
    the result's times) and the call's one :class:`~.deadline.Deadline`."""

    def __init__(self, settings, quiet, checkpoint, deadline, stop):
        self.method, self.maxiter = settings.method, settings.maxiter
        self.tol, self.options = settings.tol, settings.options
        self.quiet, self.checkpoint, self.deadline, self.stop = quiet, checkpoint, deadline, stop
        self.history, self.clock, self.kept = [], Deadline.start(), None

    def call(self, maxiter, on_iteration) -> SearchCall:
        """What a run of the method is given: ``maxiter``, the settings' tolerance and
        options, the deadline, ``on_iteration``."""
        return SearchCall(maxiter, self.tol, self.options, self.deadline, on_iteration)

    def run(self, problem, ev, u0, stage, origin: str = "the start") -> dict:
        """One method run from ``u0`` (``origin`` says what it is): the stage's
        :class:`~.result.Stage`, its objective on the stage's true targets."""
        t, first = now(), len(self.history)
        status, message = self._search(problem, ev, u0, stage, origin)
        if status == LIMIT and self.deadline.passed():
            message = f"time limit reached ({self.deadline.limit:g} s) before converging"
        status, message = judge(status, message, ev.verdict())
        ev.keep(nit=len(self.history))
        return stage_record(problem, ev.stage, nit=len(self.history) - first,
                            fun=ev.best_objective(), status=status, message=message,
                            seconds=now() - t, start=ev.start, **ev.counts(),
                            **ev.health.stage_fields())

    def _search(self, problem, ev, u0, stage, origin):
        k, count = stage
        where = "" if count == 1 else f" of stage {ev.stage} ({stage_name(problem)})"
        f0, _ = ev(u0)
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
        desc = f"{problem.name} [{self.method}]" + ("" if count == 1 else f" stage {k}/{count - 1}")
        bar = tqdm(total=self.maxiter, disable=self.quiet, desc=desc, leave=False)
        run = get_method(self.method).run
        metric = search_metric(problem)
        searched, start = (ev, u0) if metric is None else (MetricView(ev, metric),
                                                          metric.unsmooth(u0))
        before = len(self.history)
        try:
            return run(problem, searched, start,
                       self.call(self.maxiter, lambda: ev.record(self.history, self.clock, bar)))
        except GoalReached as reached:
            here = "" if count == 1 else f", {reached.iteration - before} in this stage"
            return CONVERGED, (f"converged: the goal is met at iteration {reached.iteration}"
                               f"{here} (stop='goal')")
        except KeyboardInterrupt as err:
            handled()
            signum = getattr(err, "signum", signal.SIGINT)
            who = ("by user (SIGINT)" if signum == signal.SIGINT
                   else f"by {NAMES.get(signum, signum)}")
            return INTERRUPTED, f"interrupted {who}; best result kept"
        finally:
            bar.close()
