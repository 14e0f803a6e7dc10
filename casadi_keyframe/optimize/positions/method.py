"""The transcription as a search method: ``solve(prob, method="transcription")``,
``casadi-keyframe solve P --method transcription [--option start=blend]``.

It minimises the problem's control cost (and its strain penalty, :mod:`.strain`) over the
positions of every frame with every keyframe held within ``margin`` of its tolerance
(:mod:`.sqp`), starting from the motion of
the start controls (``start="controls"``: the problem's guess, or zero forces), the start
state held still (``"rest"``; where particles are led along paths, held still relative to
them: :mod:`.rest`) or the positions blended between the keyframes' targets
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
from ...state import SimulationError
from ..finish.constraint import control_hessian
from ..options import TypedOptions, real
from ..outcome import CONVERGED, FAILED, LIMIT, ipopt_outcome
from .collocation import run_defects
from .goal import MARGIN, goal_constraints
from .interior import PositionNLP, each_iterate, search
from .replay import replay_controls
from .rest import carried_rest
from .linear_solve import LINEAR, LinearChoice
from .sqp import PositionSQP
from .stretch import StretchLimit
from .transcription import Transcription, TranscriptionError, full_forces

STARTS = ("controls", "rest", "blend")
SOLVERS = ("sqp", "ipopt")
HESSIANS = ("gauss-newton", "exact", "limited-memory")


@dataclass(frozen=True)
class TranscriptionOptions(TypedOptions):
    """``start``: where the positions start (module docstring); ``margin``: the share of
    each keyframe's tolerance held; ``settle``: converged once the goal holds and the
    control cost has changed by less than this share over the last kept steps (the search's
    ``tol`` is the gradient methods' and far finer than a trust region settles to);
    ``solver``: "sqp" (:mod:`.sqp`) or "ipopt" (:mod:`.interior`: the same effort, the
    physical stretch limit held at every spring and frame as well; ``settle`` is then
    IPOPT's ``tol``); ``hessian``: IPOPT's Hessian of the effort, its Gauss-Newton matrix
    or the exact one (:mod:`.curvature`); ``linear``: the SQP's step solved by a sparse
    factorisation ("direct"), by preconditioned conjugate gradients without forming its
    matrix ("iterative", :mod:`.linear_solve`) or by the size of the factor ("auto")."""

    label: ClassVar[str] = "the transcription"
    CHECKS: ClassVar[dict] = {
        "start": (f"one of {', '.join(STARTS)}", lambda v: v in STARTS),
        "margin": ("a number in (0, 1]", lambda v: real(v) and 0 < v <= 1),
        "settle": ("a number in (0, 1)", lambda v: real(v) and 0 < v < 1),
        "solver": (f"one of {', '.join(SOLVERS)}", lambda v: v in SOLVERS),
        "hessian": (f"one of {', '.join(HESSIANS)}", lambda v: v in HESSIANS),
        "linear": (f"one of {', '.join(LINEAR)}", lambda v: v in LINEAR)}

    start: str = "controls"
    margin: float = MARGIN
    settle: float = 1e-3
    solver: str = "sqp"
    hessian: str = "gauss-newton"
    linear: str = "auto"


def start_positions(problem, start: str, u0) -> np.ndarray:
    """The positions ``(steps + 1, n, 3)`` a search in positions starts from."""
    if start == "rest":  # held still, relative to the particles led along paths if any
        return carried_rest(problem)
    if start == "blend":
        terms = sorted((t for t in problem.objective_terms.state_terms
                        if getattr(t, "position_target", None) is not None),
                       key=lambda t: t.frame)
        return keyframe_path(problem.x0, terms, problem.steps)
    return problem.simulate(u0, records=False).x


def run(problem, ev, u0, call):
    """One search in positions (module docstring); ``(status, message)``."""
    if not full_forces(problem):  # fewer controls: the states stay unknowns beside them
        return run_defects(problem, ev, u0, call, start_positions)
    options = call.options
    if options.hessian != "gauss-newton" and options.solver != "ipopt":
        raise TranscriptionError(f"hessian={options.hessian} is IPOPT's: give solver=ipopt "
                                 "too (the SQP's matrix is the Gauss-Newton one)")
    tr = Transcription(problem)
    constraints = goal_constraints(tr, options.margin)
    start = options.start
    given = u0 is not None and not np.array_equal(np.asarray(u0), problem.initial_controls())
    if given:  # controls handed in (--resume, u0=) are where this search goes on from
        start = "controls"
    z0 = tr.unknowns(start_positions(problem, start, u0))
    replayed = []

    def offer(z):
        replayed.append(replay_controls(problem, tr.frames(z), check))
        ev.offer(replayed[-1].u)

    if options.solver == "ipopt":
        return _interior(problem, tr, constraints, z0, call, offer, replayed)

    def kept(report, point):
        if report.kept:
            offer(point.z)
        call.on_iteration()

    solver = PositionSQP(tr, constraints, control_hessian(problem),
                         LinearChoice(options.linear))
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


def _interior(problem, tr, constraints, z0, call, offer, replayed):
    """The search by IPOPT (:mod:`.interior`); ``(status, message)``."""
    if problem.limits is None or getattr(problem.model, "springs", None) is None:
        raise TranscriptionError(
            f"{problem.name}: solver=ipopt holds a cloth's springs within the physical "
            "stretch limit, and this problem has none: use solver=sqp")
    nlp = PositionNLP(tr, constraints, control_hessian(problem),
                      StretchLimit(tr, problem.limits.stretch),
                      exact=call.options.hessian == "exact")
    nlp.limited_memory = call.options.hessian == "limited-memory"

    offered = []

    def kept(z):
        offer(z)
        offered.append(z)

    each = each_iterate(kept, call)
    status, z, iterations = search(nlp, z0, maxiter=call.maxiter, tol=call.options.settle,
                                   deadline=call.deadline, on_iteration=each)
    if not offered or not np.array_equal(offered[-1], z):
        try:
            offer(z)
            offered.append(z)
        except SimulationError as err:
            replayed.append(None)
            refused = str(err)
    said = f"{iterations} IPOPT iterations in positions; " + (
        f"its last point replayed within {1e3 * replayed[-1].deviation:.1e} mm (frame "
        f"{replayed[-1].frame})" if replayed[-1] is not None else
        f"its last point is a plan the simulation refuses ({refused})")
    result, message = ipopt_outcome(status, maxiter=call.maxiter)
    return result, f"{message} ({said})"
