"""A solve's last stage with its keyframes held as a constraint (``solve(..., finish=...)``).

A penalty search stops where the keyframe term curves so sharply, or the dynamics switch so
often, that it finds no descent: a little off its keyframes, or on them with more effort
than it needs.  The finish works on the controls of the steps just before the last keyframe
(:mod:`.constrained`): ``"land"`` puts keyframes still missed within their tolerances with
the least change of the controls; ``"effort"`` lands them if needed, then lowers the
control cost while they stay within their tolerances and the objective does not rise.  Its
result replaces the search's only if it is better, by the goal first and then the
objective (:class:`~.kept.Kept`).
"""
from __future__ import annotations

import signal
from dataclasses import dataclass

from ...controls import StepForces
from ...interrupts import handled
from ..deadline import Deadline
from ..options import TypedOptions
from ..goal import verdict
from ..kept import conclude, kept_outcome
from ..outcome import CONVERGED, INTERRUPTED, LIMIT, judge
from ..result import assemble
from .constraint import KeyframeConstraint, control_hessian, factor_window
from .searches import land, lower_effort

KINDS = ("land", "effort")


@dataclass(frozen=True)
class Finish(TypedOptions):
    """``kind`` ("land" or "effort"), on the controls of the last ``window`` steps before
    the last keyframe, at most ``maxiter`` kept steps each for the landing and the effort."""

    kind: str = "effort"
    window: int = 12
    maxiter: int = 10


def finish_options(finish) -> Finish | None:
    """``finish`` (None; a dict of :class:`Finish`'s fields; a Finish) checked, naming what
    is wrong (ValueError); its text form (``"effort,window=20,maxiter=3"``) is read by the
    request (:func:`~..settings.read_kind`)."""
    opts = Finish.read(finish, "finish",
                       takes=f"one of {KINDS}, a dict of kind, window and maxiter, or None")
    if opts is None:
        return None
    if opts.kind not in KINDS:
        raise ValueError(f"finish: kind must be one of {KINDS} ('land': put missed keyframes "
                         f"within their tolerances; 'effort': then lower the control cost), "
                         f"got {opts.kind!r}")
    for name in ("window", "maxiter"):
        value = getattr(opts, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"finish: {name} must be a whole number >= 1, got {value!r}")
    return opts


def check_finish(problem, opts: Finish) -> None:
    """Refuse, before any search, a problem the finish cannot hold (ValueError naming why):
    it needs per-step forces, goals that are StateKeyframes only, and a control Hessian
    that is positive definite on the window (Smoothness with alpha > 0)."""
    if not isinstance(problem.controls, StepForces):
        raise ValueError(f"finish={opts.kind!r}: {problem.name} has "
                         f"{type(problem.controls).__name__} controls; the finish needs "
                         "per-step forces (StepForces): drop the finish")
    try:
        last = max((t.frame for t in problem.objective_terms.state_terms), default=0)
        first = KeyframeConstraint(problem, max(last - opts.window, 0)).first
    except ValueError as err:
        raise ValueError(f"finish={opts.kind!r}: {err}") from None
    block = problem.size // problem.steps
    factor_window(problem, control_hessian(problem), slice(first * block, last * block))


def run_finish(problem, result, opts: Finish, kept, deadline: Deadline | None = None):
    """The finish from ``result`` (a search's on ``problem``), until the solve's
    ``deadline``: the Result with its stages and history after the search's; where it ends
    no better or is interrupted, the best point ``kept`` holds (the search's result or a kept
    step), with a stage saying so."""
    deadline = deadline or Deadline.start()
    stages, history = list(result.stages), list(result.history)
    runs = []

    def checkpoint(u, trajectory):  # each kept step offered: the best is on disk
        kept.offer(u, "the finish's best step", trajectory=trajectory,
                   stage=stages[-1]["stage"] + 1, nit=len(history))

    try:
        u, met = result.x, _landed(problem, result.trajectory, opts.window)
        if not met:
            runs.append(land(problem, u0=u, window=opts.window, maxiter=opts.maxiter,
                             deadline=deadline, on_keep=checkpoint, gradient=result.route))
            u, met = runs[-1].x, runs[-1].status == CONVERGED
        if opts.kind == "effort" and met and not deadline.passed():
            runs.append(lower_effort(problem, u0=u, window=opts.window, maxiter=opts.maxiter,
                                     deadline=deadline, keep_objective=True,
                                     on_keep=checkpoint, gradient=result.route))
    except KeyboardInterrupt as err:
        handled()
        for run in runs:  # those that ended before the signal
            _append(stages, history, run)
        return _interrupted(problem, result, stages, history, kept, err, deadline.started)
    for run in runs:
        _append(stages, history, run)
    if not runs:
        return result
    last, began = runs[-1], deadline.started
    if not kept.offer(last.x, f"the finish ({last.method})", trajectory=last.trajectory,
                      stage=stages[-1]["stage"], nit=len(history)):
        status, message = kept_outcome(kept, result.status,
                                       f"the finish ({last.method}): {last.message}")
        return _kept(problem, result, stages, history, kept, status, message, began)
    # lowering the effort starts from a landing: a time limit there does not undo the goal
    ended = CONVERGED if last.method == "lower_effort" and last.status == LIMIT else last.status
    status, message = judge(ended, f"finish ({last.method}): {last.message}",
                            verdict(problem, last.trajectory))
    if status == CONVERGED and not message.startswith("converged"):
        message = f"converged: {message}"
    stages[-1] = {**stages[-1], "status": status, "message": message,
                  "success": status == CONVERGED}
    return assemble(problem, last.x, fun=last.fun, jac=last.jac, status=status,
                    message=message, method=result.method, route=result.route,
                    stages=stages, history=history, started=began, trajectory=last.trajectory)


def _interrupted(problem, result, stages, history, kept, err, began):
    """The Result of a finish stopped by a signal: the best point kept."""
    who = "SIGINT" if getattr(err, "signum", signal.SIGINT) == signal.SIGINT else "a signal"
    message = f"{result.message}; the finish was interrupted ({who}): {kept.where} kept"
    return _kept(problem, result, stages, history, kept, INTERRUPTED, message, began,
                 gradient=False)


def _kept(problem, result, stages, history, kept, status, message, began, gradient=True):
    """The Result at ``kept``'s point (the search's result, or a finish's step that beat
    it) with a stage that says so (:func:`~.kept.conclude`)."""
    return conclude(problem, kept, result.route, status=status, message=message,
                    stages=stages, history=history, method=result.method, started=began,
                    known=(result.x, result.fun, result.jac), gradient=gradient)


def _landed(problem, trajectory, window: int) -> bool:
    """The goal met, and the keyframes' free particles (what the finish holds) within
    their tolerances."""
    last = max((t.frame for t in problem.objective_terms.state_terms), default=0)
    constraint = KeyframeConstraint(problem, max(last - window, 0))
    return verdict(problem, trajectory).met and constraint.excess(trajectory) <= 1.0


def _append(stages, history, run) -> None:
    """``run``'s one stage and its history, numbered after those already there."""
    number = stages[-1]["stage"] + 1 if stages else 0
    stages.append({**run.stages[0], "stage": number})
    done = history[-1]["iteration"] if history else 0
    history.extend({**h, "stage": number, "iteration": done + h["iteration"]}
                   for h in run.history)
