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
the tolerance.  Its controls then
start the stage's ordinary (single-shooting) search, which stops at once if the goal is
already met and otherwise closes what the defects left.
"""
from __future__ import annotations

import time

import numpy as np

from ...interrupts import check, handled
from ...objectives import StateKeyframe
from ...state import SimulationError
from ..goal import GoalReached, verdict
from ..methods import get_method
from ..multipliers import KeyframeMultipliers, Multipliers
from ..outcome import CONVERGED, INTERRUPTED, LIMIT
from ..result import history_record, stage_record
from .form import Shooting
from .nodes import initial_nodes, reference_run
from .options import ShootingOptions
from .workers import segment_runner


class ShootingEvaluator:
    """The merit function as a search method sees it: memoised, with the best point of the
    current round (the merit changes when the multipliers move), failed simulations
    stepped back from, and what the history and the goal check need."""

    def __init__(self, shooting, runner, mult):
        self.shooting, self.runner, self.mult = shooting, runner, mult
        self.nfev = self.failures = 0
        self.seconds, self.interrupted, self.last_failure = 0.0, None, ""
        self.last_z, self.last, self.last_info, self.swept = None, None, None, None
        self.reset()

    def reset(self) -> None:
        """Forget the best point and the memo (a new round's merit: the multipliers moved)."""
        self.best_u = self.best_z = self.best_info = None
        self.best_f = np.inf
        self._judged = None
        self.last_z = self.last = None

    def __call__(self, z, force: bool = False):
        """``(merit, gradient)`` at ``z``; ``force`` evaluates again even at the last point
        (so the segments' records are z's: ``swept``)."""
        z = np.array(z, dtype=float).ravel()
        if not force and self.last_z is not None and np.array_equal(z, self.last_z):
            return self.last
        t = time.perf_counter()
        try:
            check()
            self.swept = z
            f, g, info = self.shooting.evaluate(z, self.runner, self.mult)
        except SimulationError as err:
            self.failures += 1
            self.last_failure = str(err)
            best = self.best_f if np.isfinite(self.best_f) else 0.0
            f, g, info = best + 10.0 * (abs(best) + 1.0), np.zeros_like(z), None
        self.seconds += time.perf_counter() - t
        self.nfev += 1
        self.last_z, self.last, self.last_info = z, (f, g), info
        if info is not None and f < self.best_f:
            self.best_z, self.best_u, self.best_f, self.best_info = z, z, f, info
        return f, g

    @property
    def njev(self) -> int:
        return self.nfev - self.failures


class _Variables:
    """What a search method asks of the problem: the variables' size and bounds."""

    def __init__(self, shooting):
        self.size = shooting.size
        self._bounds = shooting.bounds()

    def bounds(self):
        return self._bounds


def run_shooting(problem, opts: ShootingOptions, u0, search, stage: int, goal, export,
                 origin=None):
    """The multiple-shooting stage of ``problem`` from controls ``u0``: ``(Stage, u,
    aimed)``, ``aimed`` the problem with its keyframes aiming where the multipliers left them
    (``problem`` itself when they hold none).

    ``search`` is the solve's shared state (method, limits, history, checkpoint, clock),
    ``goal`` the problem whose keyframes judge, ``export`` maps controls to the solve's
    final problem (``origin``) for the checkpoint."""
    t = time.perf_counter()
    reference = reference_run(problem, u0)
    shooting = Shooting(problem, opts.segments, reference)
    mult = None if opts.formulation == "ipopt" else Multipliers(
        _start_weights(shooting, opts.penalty), growth=opts.growth, always=False)
    runner = segment_runner(problem, shooting.spans, opts.workers, opts.scheduler, origin)
    ev = ShootingEvaluator(shooting, runner, mult)
    z = shooting.pack(u0, initial_nodes(problem, shooting, opts.init, reference))
    first, rounds, status, message = len(search.history), 0, None, ""
    try:
        ev(z)
        if ev.failures:
            raise SimulationError(f"multiple shooting: a segment fails at the start nodes "
                                  f"({ev.last_failure}); try another init", 0)
        solve_form = _nlp if mult is None else _rounds
        status, message, rounds = solve_form(problem, opts, search, ev, z, stage, goal, export)
    except KeyboardInterrupt:
        handled()
        status, message = INTERRUPTED, "interrupted; best result kept"
    finally:
        runner.close()
    info = ev.best_info or {}
    u = shooting.unpack(ev.best_z)[0] if ev.best_z is not None else u0
    fun = true_objective(problem, u, info)[1] if info else np.nan
    record = stage_record(
        problem, stage, nit=len(search.history) - first, fun=fun, status=status,
        message=f"multiple shooting, {opts.segments} segments, {rounds} rounds: {message}",
        seconds=time.perf_counter() - t, nfev=ev.nfev, njev=ev.njev,
        evaluation_seconds=ev.seconds, failed_simulations=ev.failures,
        segments=opts.segments, defect=shooting.defect_size(info.get("defects", [])))
    return record, u, shooting.problem


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


def _rounds(problem, opts, search, ev, z, stage, goal, export):
    """The augmented-Lagrangian rounds: ``(status, message, rounds run)``."""
    shooting, run = ev.shooting, get_method(search.method).run
    variables = _Variables(shooting)
    budget = search.maxiter
    # the keyframes' weights stay the problem's: grown by the LANCELOT rule where the miss on
    # the stitched run could not shrink (the defects held it), they reached 1e7 times the
    # problem's on the 26 x 16 cape and the polish could not search the problem they left
    hard = (KeyframeMultipliers(problem, 1.0, always=False) if opts.hold and any(
        isinstance(t, StateKeyframe) for t in problem.objective_terms.state_terms) else None)
    for r in range(opts.rounds):
        ev.reset()
        maxiter = max(budget // (opts.rounds - r), 1)
        hook = _Hook(problem, search, ev, stage, goal, export, r)
        try:
            inner, said = run(variables, ev, z, maxiter, search.tol, search.options, hook,
                              search.deadline)
        except GoalReached:
            return CONVERGED, f"the goal is met in round {r}", r + 1
        budget -= hook.count
        z = ev.best_z
        c = ev.best_info["defects"]
        if inner == INTERRUPTED or search.time_up():
            return (INTERRUPTED if inner == INTERRUPTED else LIMIT), said, r + 1
        if budget <= 0:
            return LIMIT, "iteration limit reached before the goal was met", r + 1
        ev.mult.update({**{(k, "x"): cx for k, (cx, _) in enumerate(c)},
                        **{(k, "v"): cv for k, (_, cv) in enumerate(c)}})
        if hard is not None:
            hard.update(ev.best_info["trajectory"])
            shooting.problem = hard.problem()
    return LIMIT, f"{opts.rounds} rounds ended before the goal was met", opts.rounds


def true_objective(problem, u, info) -> tuple[float, float]:
    """``(keyframe error, objective)`` of ``problem`` (its true targets, not a round's aim)
    on the stitched trajectory of an evaluation's ``info``, at controls ``u``."""
    keyframe = problem.state_cost(info["trajectory"], gradient=False)[0]
    return keyframe, keyframe + problem.control_cost(u)[0]


def _nlp(problem, opts, search, ev, z, stage, goal, export):
    """IPOPT on the constrained form: ``(status, message, 1)``; its last point becomes the
    evaluator's best."""
    from .ipopt_form import run_nlp

    hook = _Hook(problem, search, ev, stage, goal, export, 0)
    try:
        options = search.options if search.method == "ipopt" else {}
        status, message, z = run_nlp(ev.shooting, ev.runner, ev, z, search.maxiter, search.tol,
                                     options, hook, search.deadline)
    except GoalReached as reached:
        return CONVERGED, f"the goal is met at iteration {reached.iteration}", 1
    ev(z)
    if ev.last_info is not None:
        ev.best_z, ev.best_u, ev.best_info = z, z, ev.last_info
    return status, message, 1


class _Hook:
    """Each iteration of a round: the history record (the problem's objective on the
    stitched trajectory, the defect), the checkpoint, and the goal check: the defects
    within their tolerance, and the controls' own run meeting the goal."""

    def __init__(self, problem, search, ev, stage, goal, export, round_):
        self.problem, self.search, self.ev = problem, search, ev
        self.stage, self.goal, self.export, self.round = stage, goal, export, round_
        self.count = 0

    def __call__(self, z=None):
        """After an iteration: of the round's best point, or of the iterate ``z``."""
        ev, search = self.ev, self.search
        self.count += 1
        if z is not None:
            ev(z)
            if ev.last_info is None:
                return
            ev.best_z, ev.best_info = np.array(z), ev.last_info
        info = ev.best_info
        u = ev.shooting.unpack(ev.best_z)[0]
        defect = ev.shooting.defect_size(info["defects"])
        keyframe, objective = true_objective(self.problem, u, info)
        search.history.append(history_record(
            self.problem, u, objective=objective,
            keyframe_error=keyframe, iteration=len(search.history) + 1,
            stage=self.stage, seconds=time.perf_counter() - search.start, nfev=ev.nfev,
            round=self.round, defect=defect))
        if search.checkpoint is not None:
            search.checkpoint.write(self.export(u), fun=float(objective),
                                    nit=len(search.history), stage=self.stage,
                                    stage_dt=float(self.problem.dt))
        check()
        if (search.stop == "goal" and defect <= 1.0 and ev.best_z is not ev._judged
                and verdict(self.goal, info["trajectory"]).met):
            ev._judged = ev.best_z
            found = verdict(self.goal, self.problem.simulate(u, records=False))
            if found.met:
                raise GoalReached(found, len(search.history))
