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
from .outcome import CONVERGED, INTERRUPTED, LIMIT
from .evaluator import evaluate_final
from .result import Result
from .search import solve


def solve_augmented(problem, *, rounds: int = 4, weight_growth: float = 1.0,
                    multipliers: bool = True, u0=None, time_limit: float | None = None,
                    **options) -> Result:
    """Solve ``problem`` in ``rounds`` rounds of :func:`solve` (``options`` go to each: method,
    gradient, maxiter per round, checkpoint, quiet, ...), each from the last round's controls,
    with the keyframes' aim moved by the multipliers and their weights times
    ``weight_growth ** round``.

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
    keyframes = [t for t in problem.objective_terms.terms if isinstance(t, StateKeyframe)]
    if not keyframes:
        raise ValueError(f"{problem.name}: no StateKeyframe term to hold hard; an augmented "
                         "Lagrangian needs a state target (positions and/or velocities)")
    shifts = {id(t): (0.0, 0.0) for t in keyframes}  # lambda / w, positions and velocities
    u = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    history, stages, start = [], [], time.perf_counter()
    for k in range(rounds):
        scale = float(weight_growth) ** k
        p = _with_keyframes(problem, shifts, scale)
        left = None if time_limit is None else max(time_limit - (time.perf_counter() - start),
                                                   1e-3)
        res = solve(p, u0=u, time_limit=left, **options)
        u = res.x
        history += [{**h, "round": k, "iteration": len(history) + i + 1}
                    for i, h in enumerate(res.history)]
        traj = res.trajectory  # the dynamics do not depend on the keyframes' aim
        breakdown = problem.breakdown(u, traj)
        stages.append({"stage": k, "weight_scale": scale, "nit": res.nit, "nfev": res.nfev,
                       "seconds": res.timings["wall_seconds"], "fun": breakdown["objective"],
                       "control_cost": breakdown["control_cost"],
                       "misses": breakdown["misses"], "status": res.status,
                       "message": res.message, **{f"start_{k}": v for k, v in
                                                  res.start.items()}})
        if res.status == INTERRUPTED or _time_up(time_limit, start):
            break
        if multipliers:
            for t in keyframes:
                sx, sv = shifts[id(t)]
                # lambda += w_k c  =>  lambda / w_{k+1} = (shift + c) / growth
                shifts[id(t)] = tuple((s + c) / weight_growth for s, c in zip(
                    (sx, sv), _residual(t, traj)))
    f, g = evaluate_final(problem, get_gradient(options.get("gradient", "adjoint")), u)
    status, message = res.status, f"{len(stages)} augmented-Lagrangian rounds; last: {res.message}"
    if len(stages) < rounds and status != INTERRUPTED:
        status, message = LIMIT, (f"time limit reached ({time_limit:g} s) after round "
                                  f"{len(stages) - 1} of 0..{rounds - 1}; last: {res.message}")
    return Result(x=u, fun=float(f), jac=g, nit=sum(s["nit"] for s in stages),
                  nfev=sum(s["nfev"] for s in stages), success=status == CONVERGED,
                  status=status, message=message,
                  method=res.method, gradient=res.gradient, trajectory=traj, history=history,
                  timings={"wall_seconds": time.perf_counter() - start,
                           "stage_seconds": [s["seconds"] for s in stages]},
                  breakdown=problem.breakdown(u, traj), stages=stages)


def _time_up(time_limit, start) -> bool:
    return time_limit is not None and time.perf_counter() - start >= time_limit


def _with_keyframes(problem, shifts, scale):
    """``problem`` with each StateKeyframe aiming at ``target - shift`` with weights times
    ``scale`` (the problem itself in round 0 of a plain start)."""
    if scale == 1.0 and all(np.all(np.equal(s, 0.0)) for pair in shifts.values() for s in pair):
        return problem
    terms = [t.moved(-shifts[id(t)][0], -shifts[id(t)][1], scale) if id(t) in shifts else t
             for t in problem.objective_terms.terms]
    return problem.with_objective(Objective(terms))


def _residual(term, traj):
    """``(x_N - x*, v_N - v*)`` of a keyframe over its particles (0 where it has no target)."""
    idx, x, v = term.particles, term.position_target, term.velocity_target
    dx = 0.0 if x is None else traj.x[term.frame][idx] - x
    dv = 0.0 if v is None else traj.v[term.frame][idx] - v
    return dx, dv
