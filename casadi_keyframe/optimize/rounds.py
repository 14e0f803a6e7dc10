"""Hard keyframes by an augmented Lagrangian: the rounds, a stage of :func:`~.search.solve`
(``rounds=``, :class:`Rounds`), each running the solve's other stages on the problem its
keyframes aim in.

A keyframe weight w turns ``q_N = q*`` into a penalty, and the optimum of ``control cost +
0.5 w |q_N - q*|^2`` misses by about (control cost's pull) / w.  Raising w shrinks the miss
but makes the problem stiffer for L-BFGS-B.  The augmented Lagrangian keeps w and adds a
multiplier: ``0.5 w |q_N - q* + lambda / w|^2``, i.e. the keyframe aims past its target by
``lambda / w`` (:meth:`~casadi_keyframe.objectives.StateKeyframe.aiming`); after each round
``lambda += w (q_N - q*)`` (:class:`~.multipliers.Multipliers`, the mechanism multiple
shooting's defects share).  ``weight_growth`` > 1 also stiffens w per round (a penalty
schedule); with ``multipliers=False`` that schedule alone is run.  The rounds stop early
once every keyframe is within its tolerance (with ``stop="goal"``, the default where
tolerances exist), and each round is judged by the true targets, which do not move.

Only :class:`~casadi_keyframe.objectives.StateKeyframe` terms (full or per-particle state
targets) get multipliers; other terms stay as they are.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kept import Kept, conclude, evaluate_final, kept_outcome
from .goal import verdict
from .multipliers import KeyframeMultipliers
from .options import TypedOptions
from .outcome import INTERRUPTED, LIMIT
from .result import Result, assemble, stage_record


@dataclass(frozen=True)
class Rounds(TypedOptions):
    """Augmented-Lagrangian rounds: at most ``rounds`` of them, the keyframe weights times
    ``weight_growth`` per round (1: the multipliers alone), ``multipliers`` (False: the
    penalty schedule alone)."""

    rounds: int = 4
    weight_growth: float = 1.0
    multipliers: bool = True


def rounds_options(value) -> Rounds | None:
    """``value`` (None, a number of rounds, a dict of :class:`Rounds`' fields, or one) as
    checked rounds, or None for none; ValueError naming what is wrong."""
    opts = Rounds.read(value, "rounds", single=(int, np.integer),
                       takes="a number of rounds, a dict of rounds, weight_growth and "
                             "multipliers, or None")
    if opts is None:
        return None
    if isinstance(opts.rounds, bool) or not (isinstance(opts.rounds, (int, np.integer))
                                             and opts.rounds >= 1):
        raise ValueError(f"rounds must be a whole number >= 1, got {opts.rounds!r}")
    growth = opts.weight_growth
    if isinstance(growth, bool) or not (isinstance(growth, (int, float, np.number))
                                        and np.isfinite(growth) and growth >= 1):
        raise ValueError(f"weight_growth must be >= 1 (1: multipliers alone), got {growth}")
    return opts


def run_rounds(problem, rounds: Rounds, run, *, u0, resume, checkpoint, deadline,
               stop: str) -> Result:
    """The rounds of ``problem`` from ``u0`` (default: its start): ``run(aimed, u,
    checkpoint)`` runs the solve's other stages on ``aimed`` (the problem with its keyframes
    aiming past their targets by the multipliers' shifts, their weights times
    ``weight_growth ** round``) from the last round's controls, judged by ``problem``.

    The result is ``problem``'s (objective, breakdown and trajectory with the true targets
    and weights) at the last round's controls, or at an earlier round's (or the start) that
    was better by the goal; ``stages`` has one entry per round with its weight scale,
    iterations, evaluations, seconds, objective and the keyframes' misses; ``nit``, ``nfev``
    and ``history`` run over all rounds.  The ``status`` is the last round's, judged by the
    true targets; the rounds end early when the goal is met (``stop="goal"``), on a signal
    (status 3) or at the ``deadline`` (status 1).  The ``checkpoint`` carries the round and
    the multipliers, and ``resume`` (a checkpoint's metadata) starts from them, so a resumed
    run goes on where it stopped.
    """
    hard = KeyframeMultipliers(problem, rounds.weight_growth)
    first = hard.resume(resume)
    u = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    history, stages, last = [], [], max(rounds.rounds, first + 1)
    kept = Kept(problem, problem, hard.checkpoint(checkpoint, first), by_objective=False)
    kept.offer(u, "its start")
    res = None
    for k in range(first, last):
        res = run(hard.problem(), u, hard.checkpoint(checkpoint, k))
        u, traj = res.x, res.trajectory  # the dynamics do not depend on the keyframes' aim
        history += [{**h, "round": k, "iteration": len(history) + i + 1}
                    for i, h in enumerate(res.history)]
        stages.append(_round(problem, k, hard.scale, res))
        kept.offer(u, f"round {k}'s result", trajectory=traj, stage=k, nit=len(history))
        if (res.status == INTERRUPTED or deadline.passed()
                or (stop == "goal" and verdict(problem, traj).met)):
            break
        hard.update(traj, rounds.multipliers)
    status, message = res.status, f"{len(stages)} augmented-Lagrangian rounds; last: {res.message}"
    if stages[-1]["stage"] < last - 1 and res.status != INTERRUPTED and deadline.passed():
        status, message = LIMIT, (f"time limit reached ({deadline.limit:g} s) after round "
                                  f"{stages[-1]['stage']} of 0..{last - 1}; last: "
                                  f"{res.message}")
    if kept.u is not u:  # an earlier round, or the start, was better than the last
        status, message = kept_outcome(kept, status, message)
        return conclude(problem, kept, res.route, status=status, message=message,
                        stages=stages, history=history, method=res.method,
                        started=deadline.started)
    f, g = evaluate_final(problem, res.route, u)
    return assemble(problem, u, fun=f, jac=g, status=status, message=message,
                    method=res.method, route=res.route, stages=stages, history=history,
                    started=deadline.started, trajectory=traj)


def _round(problem, k, scale, res) -> dict:
    """Round ``k``'s :class:`~.result.Stage`: its solve's totals and how it ended, with the
    true problem's objective, control cost and misses at its controls."""
    breakdown = problem.breakdown(res.x, res.trajectory)
    return stage_record(problem, k, nit=res.nit, nfev=res.nfev, njev=res.njev,
                        fun=breakdown["objective"], status=res.status, message=res.message,
                        seconds=res.timings["wall_seconds"],
                        evaluation_seconds=res.timings["evaluation_seconds"],
                        failed_simulations=res.timings["failed_simulations"],
                        start=(res.start["objective"], res.start["keyframe_error"]),
                        weight_scale=scale, control_cost=breakdown["control_cost"],
                        misses=breakdown["misses"])

