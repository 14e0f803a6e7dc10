"""Hard keyframes by an augmented Lagrangian around :func:`~.search.solve`.

A keyframe weight w turns ``q_N = q*`` into a penalty, and the optimum of ``control cost +
0.5 w |q_N - q*|^2`` misses by about (control cost's pull) / w.  Raising w shrinks the miss
but makes the problem stiffer for L-BFGS-B.  The augmented Lagrangian keeps w and adds a
multiplier: ``0.5 w |q_N - q* + lambda / w|^2``, i.e. the keyframe aims at ``q* - lambda /
w``; after each round ``lambda += w (q_N - q*)``, so the aim moves past the target by the
miss that is left (the classical method of multipliers).  ``weight_growth`` > 1 also stiffens
w per round (a penalty schedule); with ``multipliers=False`` that schedule alone is run.

Only :class:`~casadi_keyframe.objectives.StateKeyframe` terms (full or per-particle state
targets) get multipliers; other terms stay as they are.
"""
from __future__ import annotations

import time

import numpy as np

from ..adjoints import get_gradient
from ..objectives import Objective, StateKeyframe
from .evaluator import evaluate_final
from .outcome import INTERRUPTED, LIMIT
from .result import Result, assemble
from .search import solve


def solve_augmented(problem, *, rounds: int = 4, weight_growth: float = 1.0,
                    multipliers: bool = True, u0=None, time_limit: float | None = None,
                    **options) -> Result:
    """Solve ``problem`` in ``rounds`` rounds of :func:`~.search.solve` (``options`` go to
    each: method, gradient, maxiter per round, checkpoint, quiet, ...), each from the last
    round's controls, with the keyframes' aim moved by the multipliers and their weights
    times ``weight_growth ** round``.

    The result is ``problem``'s (objective, breakdown and trajectory with the true targets
    and weights) at the last round's controls; ``stages`` has one entry per round with its
    weight scale, iterations, evaluations, seconds, objective and the keyframes' misses;
    ``nit``, ``nfev`` and ``history`` run over all rounds.  The ``status`` is the last
    round's; Ctrl-C (status 3) or ``time_limit`` (seconds over all rounds, status 1) ends the
    rounds there.
    """
    if not (isinstance(rounds, (int, np.integer)) and rounds >= 1):
        raise ValueError(f"rounds must be a whole number >= 1, got {rounds!r}")
    if not (np.isfinite(weight_growth) and weight_growth >= 1):
        raise ValueError(f"weight_growth must be >= 1 (1: multipliers alone), got {weight_growth}")
    terms = problem.objective_terms.terms
    keyframes = [i for i, t in enumerate(terms) if isinstance(t, StateKeyframe)]
    if not keyframes:
        raise ValueError(f"{problem.name}: no StateKeyframe term to hold hard; an augmented "
                         "Lagrangian needs a state target (positions and/or velocities)")
    # lambda / w per keyframe, positions and velocities, keyed by the term's place in the
    # objective: each round's problem holds moved copies of the terms, in the same places
    shifts = {i: (0.0, 0.0) for i in keyframes}
    u = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    history, stages, start = [], [], time.perf_counter()
    for k in range(rounds):
        scale = float(weight_growth) ** k
        left = None if time_limit is None else max(time_limit - (time.perf_counter() - start),
                                                   1e-3)
        res = solve(_with_keyframes(problem, shifts, scale), u0=u, time_limit=left, **options)
        u, traj = res.x, res.trajectory  # the dynamics do not depend on the keyframes' aim
        history += [{**h, "round": k, "iteration": len(history) + i + 1}
                    for i, h in enumerate(res.history)]
        stages.append(_round(problem, k, scale, res))
        if res.status == INTERRUPTED or _time_up(time_limit, start):
            break
        if multipliers:
            for i in keyframes:
                # lambda += w_k c  =>  lambda / w_{k+1} = (shift + c) / growth
                shifts[i] = tuple((s + c) / weight_growth for s, c in zip(
                    shifts[i], _residual(terms[i], traj)))
    f, g = evaluate_final(problem, get_gradient(options.get("gradient", "adjoint")), u)
    status, message = res.status, f"{len(stages)} augmented-Lagrangian rounds; last: {res.message}"
    if len(stages) < rounds and status != INTERRUPTED:
        status, message = LIMIT, (f"time limit reached ({time_limit:g} s) after round "
                                  f"{len(stages) - 1} of 0..{rounds - 1}; last: {res.message}")
    return assemble(problem, u, fun=f, jac=g, status=status, message=message,
                    method=res.method, gradient=res.gradient, stages=stages, history=history,
                    started=start, trajectory=traj)


def _round(problem, k, scale, res) -> dict:
    """Round ``k``'s :class:`~.result.Stage`: its solve's totals and how it ended, with the
    true problem's objective, control cost and misses at its controls."""
    breakdown = problem.breakdown(res.x, res.trajectory)
    return {"stage": k, "dt": problem.dt, "steps": problem.steps,
            "particles": problem.model.n, "weight_scale": scale, "nit": res.nit,
            "nfev": res.nfev, "njev": res.njev, "seconds": res.timings["wall_seconds"],
            "evaluation_seconds": res.timings["evaluation_seconds"],
            "failed_simulations": res.timings["failed_simulations"],
            "fun": breakdown["objective"], "control_cost": breakdown["control_cost"],
            "misses": breakdown["misses"], "success": res.success, "status": res.status,
            "message": res.message, "start_objective": res.start["objective"],
            "start_keyframe_error": res.start["keyframe_error"]}


def _time_up(time_limit, start) -> bool:
    return time_limit is not None and time.perf_counter() - start >= time_limit


def _with_keyframes(problem, shifts, scale):
    """``problem`` with each StateKeyframe (its index among the objective's terms a key of
    ``shifts``) aiming at ``target - shift`` with weights times ``scale`` (the problem
    itself in round 0 of a plain start)."""
    if scale == 1.0 and all(np.all(np.equal(s, 0.0)) for pair in shifts.values() for s in pair):
        return problem
    terms = [t.moved(-shifts[i][0], -shifts[i][1], scale) if i in shifts else t
             for i, t in enumerate(problem.objective_terms.terms)]
    return problem.with_objective(Objective(terms))


def _residual(term, traj):
    """``(x_N - x*, v_N - v*)`` of a keyframe over its particles (0 where it has no target)."""
    idx, x, v = term.particles, term.position_target, term.velocity_target
    dx = 0.0 if x is None else traj.x[term.frame][idx] - x
    dv = 0.0 if v is None else traj.v[term.frame][idx] - v
    return dx, dv
