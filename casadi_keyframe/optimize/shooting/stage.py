"""Multiple shooting as a stage of :func:`~.search.solve` (``shooting=K``).

The stage minimises the problem's objective over the controls and the node states with
the segments' defects held by an augmented Lagrangian (:class:`~.multipliers.Multipliers`
shared with the keyframe rounds): rounds of the search method (L-BFGS-B by default) on the
merit function, the multipliers moved by the defects left and the weights grown where a
defect did not shrink, until the defects are within the keyframes' tolerances and the
controls, simulated from the start as one trajectory, meet the goal.  The StateKeyframes
are held the same way (``hold``): their multipliers move their aim by the miss left where
it shrank to a quarter since the last round (their weights stay the problem's), since the
penalty's own optimum misses by the control cost's pull over the weight, which can exceed
the tolerance.  Its controls then start the stage's ordinary (single-shooting) search,
which stops at once if the goal is already met and otherwise closes what the defects left.
Its points go through the optimizer's own :class:`~.evaluator.Evaluator`, of the merit
(:class:`~.merit.ShootingMerit`), each iteration recording the round's best point.
"""
from __future__ import annotations

import numpy as np

from ...interrupts import handled
from ...objectives import StateKeyframe
from ...state import SimulationError
from ..deadline import now
from ..evaluator import Evaluator
from ..goal import GoalReached
from ..methods import get_method
from ..multipliers import KeyframeMultipliers, Multipliers
from ..outcome import CONVERGED, INTERRUPTED, LIMIT
from ..result import stage_record
from .form import Shooting
from .merit import ShootingMerit, true_objective
from .nodes import initial_nodes, reference_run
from .options import ShootingOptions
from .placement import growth_spans, step_growth
from .workers import segment_runner


def run_shooting(problem, opts: ShootingOptions, u0, search, stage: int, goal, export,
                 origin=None):
    """The multiple-shooting stage of ``problem`` from controls ``u0``: ``(Stage, u,
    aimed)``, ``aimed`` the problem with its keyframes aiming where the multipliers left them
    (``problem`` itself when they hold none).

    ``search`` is the solve's shared state (method, limits, history, checkpoint, clock),
    ``goal`` the problem whose keyframes judge, ``export`` maps controls to the solve's
    final problem (``origin``) for the checkpoint."""
    t = now()
    reference = reference_run(problem, u0)
    spans = (growth_spans(step_growth(problem, u0), opts.segments) if opts.place == "growth"
             else None)
    shooting = Shooting(problem, opts.segments, reference, spans=spans)
    mult = None if opts.formulation == "ipopt" else Multipliers(
        _start_weights(shooting, opts.penalty), growth=opts.growth, always=False)
    runner = segment_runner(problem, shooting.spans, opts.workers, opts.scheduler, origin)
    ev = Evaluator(problem, None, search.checkpoint, stage=stage, export=export, goal=goal,
                   stop=search.stop, merit=ShootingMerit(problem, shooting, runner, mult),
                   failed_best=False, final=False)
    z = shooting.pack(u0, initial_nodes(problem, shooting, opts.init, reference))
    first, rounds, status, message = len(search.history), 0, None, ""
    try:
        ev(z)
        if ev.failures:
            raise SimulationError(f"multiple shooting: a segment fails at the start nodes "
                                  f"({ev.last_failure}); try another init", 0)
        solve_form = _nlp if mult is None else _rounds
        status, message, rounds = solve_form(problem, opts, search, ev, z)
    except KeyboardInterrupt:
        handled()
        status, message = INTERRUPTED, "interrupted; best result kept"
    finally:
        runner.close()
    info = ev.best_info
    u = shooting.unpack(ev.best_u)[0] if ev.best_u is not None else u0
    fun = true_objective(problem, u, info)[1] if info is not None else np.nan
    record = stage_record(
        problem, stage, nit=len(search.history) - first, fun=fun, status=status,
        message=f"multiple shooting, {opts.segments} segments{_placed(shooting, opts)}, "
                f"{rounds} rounds: {message}",
        seconds=now() - t, **ev.counts(), segments=opts.segments,
        defect=shooting.defect_size(info.defects if info is not None else []))
    return record, u, shooting.problem


def _placed(shooting, opts) -> str:
    """`` (at frames 12, 30, ...)`` where the segments were placed by growth."""
    if opts.place != "growth":
        return ""
    return f" (at frames {', '.join(str(a) for a, _ in shooting.spans[1:])}, by growth)"


def _start_weights(shooting, penalty) -> dict:
    """Each defect block's starting weight, in the scaled defects' units: what a miss of the
    tolerance's size at the keyframes costs (their largest weight per particle), times
    ``penalty``."""
    wx = wv = 0.0
    for term in shooting.problem.objective_terms.state_terms:
        if isinstance(term, StateKeyframe):
            wx, wv = max(wx, term.position_weight), max(wv, term.velocity_weight)
    sx, sv = shooting.sigma
    wx = wx or 1.0
    wv = wv or wx * 0.1 ** 2
    return {(k, c): penalty * w for k in range(shooting.K - 1)
            for c, w in (("x", wx * sx ** 2), ("v", wv * sv ** 2))}


def _rounds(problem, opts, search, ev, z):
    """The augmented-Lagrangian rounds: ``(status, message, rounds run)``."""
    shooting, mult, run = ev.merit.shooting, ev.merit.mult, get_method(search.method).run
    budget = search.maxiter
    # the keyframes' weights stay the problem's: grown by the LANCELOT rule where the miss on
    # the stitched run could not shrink (the defects held it), they reached 1e7 times the
    # problem's on the 26 x 16 cape and the polish could not search the problem they left
    hard = (KeyframeMultipliers(problem, 1.0, always=False) if opts.hold and any(
        isinstance(t, StateKeyframe) for t in problem.objective_terms.state_terms) else None)
    for r in range(opts.rounds):
        ev.reset()
        maxiter, before = max(budget // (opts.rounds - r), 1), len(search.history)
        try:
            inner, said = run(shooting, ev, z, search.call(
                maxiter, lambda r=r: ev.record(search.history, search.clock, round=r)))
        except GoalReached:
            return CONVERGED, f"the goal is met in round {r}", r + 1
        budget -= len(search.history) - before
        z = ev.best_u
        c = ev.best_info.defects
        if inner == INTERRUPTED or search.deadline.passed():
            return (INTERRUPTED if inner == INTERRUPTED else LIMIT), said, r + 1
        if budget <= 0:
            return LIMIT, "iteration limit reached before the goal was met", r + 1
        mult.update({**{(k, "x"): cx for k, (cx, _) in enumerate(c)},
                     **{(k, "v"): cv for k, (_, cv) in enumerate(c)}})
        if hard is not None:
            hard.update(ev.best_info.trajectory)
            shooting.problem = hard.problem()
    return LIMIT, f"{opts.rounds} rounds ended before the goal was met", opts.rounds


def _nlp(problem, opts, search, ev, z):
    """IPOPT on the constrained form: ``(status, message, 1)``; each iterate, and its last
    point, becomes the evaluator's best."""
    from ..methods.ipopt import IpoptOptions
    from .ipopt_form import run_nlp

    def on_iteration(x):
        if ev.take(x):
            ev.record(search.history, search.clock, round=0)

    try:
        options = search.options.as_dict() if isinstance(search.options, IpoptOptions) else {}
        status, message, z = run_nlp(ev.merit.shooting, ev.merit.runner, ev, z, search.maxiter,
                                     search.tol, options, on_iteration, search.deadline)
    except GoalReached as reached:
        return CONVERGED, f"the goal is met at iteration {reached.iteration}", 1
    ev.take(z)
    return status, message, 1
