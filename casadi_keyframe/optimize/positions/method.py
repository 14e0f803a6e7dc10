"""The transcription as a search method: ``solve(prob, method="transcription")``,
``casadi-keyframe solve P --method transcription [--option start=blend]``.

It minimises the problem's control cost (and its strain penalty, :mod:`.strain`) over the
positions of every frame with every keyframe held within ``margin`` of its tolerance
(:mod:`.sqp`), starting from the motion of
the start controls (``start="controls"``: the problem's guess, or zero forces), the start
state held still (``"rest"``) or the positions blended between the keyframes' targets
(``"blend"``); controls handed in (``--resume``, ``u0=``) override ``start``: the search
goes on from their motion.  Each kept iterate's controls are replayed along its positions
(:mod:`.replay`) and offered to the evaluator, which judges and keeps the best as for any
method; the result's controls replay through ``simulate``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...interrupts import check
from ...objectives.paths import keyframe_path
from ..finish.constraint import control_hessian
from ..options import TypedOptions, real
from ..outcome import CONVERGED, FAILED, LIMIT
from .goal import MARGIN, goal_constraints
from .replay import replay_controls
from .sqp import PositionSQP
from .transcription import Transcription

STARTS = ("controls", "rest", "blend")


@dataclass(frozen=True)
class TranscriptionOptions(TypedOptions):
    """``start``: where the positions start (module docstring); ``margin``: the share of
    each keyframe's tolerance held; ``settle``: converged once the goal holds and the
    control cost has changed by less than this share over the last kept steps (the search's
    ``tol`` is the gradient methods' and far finer than a trust region settles to)."""

    label: ClassVar[str] = "the transcription"
    CHECKS: ClassVar[dict] = {
        "start": (f"one of {', '.join(STARTS)}", lambda v: v in STARTS),
        "margin": ("a number in (0, 1]", lambda v: real(v) and 0 < v <= 1),
        "settle": ("a number in (0, 1)", lambda v: real(v) and 0 < v < 1)}

    start: str = "controls"
    margin: float = MARGIN
    settle: float = 1e-3


def start_positions(problem, start: str, u0) -> np.ndarray:
    """The positions ``(steps + 1, n, 3)`` a search in positions starts from."""
    if start == "rest":
        return np.repeat(problem.x0[None], problem.steps + 1, axis=0)
    if start == "blend":
        terms = sorted((t for t in problem.objective_terms.state_terms
                        if getattr(t, "position_target", None) is not None),
                       key=lambda t: t.frame)
        return keyframe_path(problem.x0, terms, problem.steps)
    return problem.simulate(u0, records=False).x


def run(problem, ev, u0, call):
    """One search in positions (module docstring); ``(status, message)``."""
    options = call.options
    tr = Transcription(problem)
    constraints = goal_constraints(tr, options.margin)
    solver = PositionSQP(tr, constraints, control_hessian(problem))
    start = options.start
    given = u0 is not None and not np.array_equal(np.asarray(u0), problem.initial_controls())
    if given:  # controls handed in (--resume, u0=) are where this search goes on from
        start = "controls"
    z0 = tr.unknowns(start_positions(problem, start, u0))
    replayed = []

    def kept(report, point):
        if report.kept:
            replayed.append(replay_controls(problem, tr.frames(point.z), check))
            ev.offer(replayed[-1].u)
        call.on_iteration()

    outcome, _ = solver.run(z0, maxiter=call.maxiter, tol=options.settle, on_iteration=kept,
                            should_stop=lambda: (check() or False) or call.deadline.passed())
    said = f"{outcome.iterations} iterations in positions" + (
        f" from the given controls' motion (not start={options.start})"
        if given and options.start != start else "") + (
        "" if not replayed else f"; the last kept plan replayed within "
        f"{1e3 * replayed[-1].deviation:.1e} mm (frame {replayed[-1].frame})")
    if outcome.reason == "converged":
        return CONVERGED, (f"converged: the control cost settled (within {options.settle:g} "
                           f"over the last kept steps) with the keyframes held ({said})")
    if outcome.reason == "stopped":
        return LIMIT, f"time limit reached ({said})"
    if outcome.reason == "stalled":
        return FAILED, f"no step lowers the merit any further ({said})"
    return LIMIT, f"maxiter reached ({said})"
