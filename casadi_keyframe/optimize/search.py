"""One optimisation of a problem's controls: :func:`solve`.

It checks what it is asked before any simulation, goes through the stages
(:mod:`.stages`) coarse to fine, runs the method of :data:`~.methods.METHODS` on each
through an :class:`~.evaluator.Evaluator`, and returns a :class:`~.result.Result` in scipy's
vocabulary (``status`` included, see :mod:`.outcome`).  Ctrl-C (or any
:class:`~casadi_keyframe.interrupts.Interrupted`) stops the solve and returns the best
controls seen so far with status 3; ``time_limit=`` stops it with status 1; with
``checkpoint=`` the best is also on disk after every iteration, written atomically.
"""
from __future__ import annotations

import math
import numbers
import signal
from dataclasses import replace

import numpy as np

from tqdm.auto import tqdm

from ..adjoints import get_gradient
from ..health import GradientError
from ..interrupts import NAMES, handled
from ..saved import as_checkpoint
from ..state import SimulationError
from .deadline import Deadline, now
from .evaluator import Evaluator, MetricView
from .finish import check_finish, finish_options, run_finish
from .goal import GoalReached, check_stop
from .kept import Kept, conclude, evaluate_final, kept_outcome
from .methods import check_options, get_method
from .metrics import search_metric
from .outcome import CONVERGED, INTERRUPTED, LIMIT, judge
from .shooting import run_shooting, shooting_options
from .result import Result, assemble, stage_record
from .stages import carry, stage_name, stage_problems



def solve(problem, method: str = "lbfgsb", *, gradient="adjoint", maxiter: int = 200,
          tol: float = 1e-8, u0=None, quiet: bool = False, checkpoint=None,
          options: dict | None = None, continuation=None, resolutions=None,
          time_limit: float | None = None, stop: str | None = None, goal=None,
          shooting=None, homotopy=None, finish=None) -> Result:
    """Optimise the problem's controls; a :class:`~.result.Result` (scipy's vocabulary).

    ``method``: a :data:`~.methods.METHODS` entry; ``gradient``: a route (name or object);
    ``maxiter`` (per stage) and ``tol``: the method's limits; ``u0``: the start (default the
    problem's guess, else passive); ``options``: the method library's own (unknown names
    refused up front); ``time_limit``: seconds, wall clock, over all stages; ``checkpoint``:
    a ``.npz`` path or Checkpoint that always holds the best point judged so far.  Stages,
    coarse to fine: ``resolutions`` (coarser meshes), ``homotopy`` (levels of the model),
    ``continuation`` (coarser time steps), each with ``shooting`` (multiple shooting, K
    segments or its options) if given.  ``stop``: ``"goal"`` (the default where keyframes
    declare tolerances) stops once the goal is met, ``"method"`` at the method's own test;
    ``goal``: the problem that judges (default ``problem``).  ``finish``: a last stage with
    the keyframes held as a constraint (:mod:`.finish`: ``"land"``, ``"effort"`` or its
    options).  The result is never worse than the start, by the goal first and then the
    objective.  Each argument and stage in full:
    ``docs/explanations/solving.md``.
    """
    options = check_settings(method, maxiter, tol, time_limit, options)
    stop = check_stop(stop, goal or problem)
    finishing = finish_options(finish)
    if finishing is not None:
        check_finish(problem, finishing)
    multiple = shooting_options(shooting)
    shooting_on = multiple is not None and multiple.segments > 1
    problems = stage_problems(problem, continuation, resolutions, homotopy)
    strategy = get_gradient(gradient)
    search = _Search(method, maxiter, tol, options, quiet, as_checkpoint(checkpoint),
                     time_limit)
    search.stop = stop
    start = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    kept = Kept(problem, goal or problem, search.checkpoint)
    if len(problems) > 1 or shooting_on:  # stages that may end worse than the start
        kept.offer(start, "its start")
    u = None if u0 is None else carry(problem, start, problems[0])
    stages = []
    for k, p in enumerate(problems):
        final = p is problem
        export = lambda v, p=p: carry(p, v, problem)  # noqa: E731
        ev = Evaluator(p, strategy, search.checkpoint, stage=len(stages), export=export,
                       goal=(goal or problem) if final else p, stop=stop, final=final)
        begin, polish = p.initial_controls() if u is None else u, True
        origin = ("the start" if k == 0 else
                  f"stage {stages[-1]['stage']}'s best, carried here" if stages else "the start")
        if shooting_on:
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
    result = _result(problem, p, ev, strategy, search, stages, kept)
    if finishing is None or result.status == INTERRUPTED or search.deadline.passed():
        return result
    return run_finish(problem, result, finishing, kept, search.deadline)


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
                           export=ev.export, goal=ev.goal, stop=ev.stop, final=ev.final)
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


def check_settings(method, maxiter, tol, time_limit, options) -> dict:
    """Refuse a setting of :func:`solve` before any simulation runs (ValueError naming it
    and what it takes); return the method's options, checked, as a new dict."""
    get_method(method)
    if isinstance(maxiter, bool) or not isinstance(maxiter, numbers.Integral) or maxiter < 1:
        raise ValueError(f"maxiter must be a whole number >= 1 (iterations per stage), got "
                         f"{maxiter!r}")
    if not _positive(tol):
        raise ValueError(f"tol must be a finite number > 0 (the method's convergence "
                         f"tolerance), got {tol!r}")
    if time_limit is not None and not _positive(time_limit):
        raise ValueError(f"time_limit must be a finite positive number of seconds (None for "
                         f"no limit), got {time_limit!r}")
    return check_options(method, options)


def _positive(value) -> bool:
    return (isinstance(value, numbers.Real) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0)


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
            message = f"time limit reached ({search.time_limit:g} s) before converging"
        message = (f"{message}, in stage {stages[-1]['stage']} ({stage_name(p)}): its best "
                   f"controls, carried to the problem ({stage_name(problem)}), kept")
    trajectory = problem.simulate(u)
    if kept.beats(u, trajectory):
        status, message = kept_outcome(kept, status, message)
        return conclude(problem, kept, strategy, status=status, message=message,
                        stages=stages, history=search.history, method=search.method,
                        started=search.deadline.started)
    # the checkpoint holds the result too (a coarse stage's, carried, once judged here)
    kept.offer(u, "the result", trajectory=trajectory, stage=stages[-1]["stage"],
               nit=len(search.history))
    return assemble(problem, u, fun=fun, jac=jac, status=status, message=message,
                    method=search.method, route=strategy,
                    stages=stages, history=search.history, started=search.deadline.started,
                    trajectory=trajectory)


class _Search:
    """What the stages of one :func:`solve` share: the method and its settings, the
    history, the checkpoint and the one :class:`~.deadline.Deadline`."""

    def __init__(self, method, maxiter, tol, options, quiet, checkpoint, time_limit):
        self.method, self.maxiter, self.tol, self.options = method, maxiter, tol, options
        self.quiet, self.checkpoint, self.time_limit = quiet, checkpoint, time_limit
        self.stop = "method"
        self.history, self.deadline = [], Deadline.start(time_limit)

    def run(self, problem, ev, u0, stage, origin: str = "the start") -> dict:
        """One method run from ``u0`` (``origin`` says what it is): the stage's
        :class:`~.result.Stage`, its objective on the stage's true targets."""
        t, first = now(), len(self.history)
        status, message = self._search(problem, ev, u0, stage, origin)
        if status == LIMIT and self.deadline.passed():
            message = f"time limit reached ({self.time_limit:g} s) before converging"
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
            return run(problem, searched, start, self.maxiter, self.tol, self.options,
                       lambda: ev.record(self.history, self.deadline, bar), self.deadline)
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
