"""Optimizers: L-BFGS-B (scipy) and IPOPT (CasADi nlpsol fed by a Callback).

Both return a :class:`Result` in scipy's vocabulary (``status`` included, see
:mod:`.outcome`) plus the trajectory, a per-iteration history and timings.  Ctrl-C (or any
:class:`~.interrupts.Interrupted`) stops the solve and returns the best controls seen so
far with status 3; ``time_limit=`` stops it with status 1; with ``checkpoint=`` the best is
also on disk after every iteration, written atomically.  ``continuation=`` solves at coarse
time steps first, ``resolutions=`` on coarser meshes, then refines (see :func:`solve`; the
stages themselves: :mod:`.stages`).
"""
from __future__ import annotations

import signal
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.optimize import minimize
from tqdm.auto import tqdm

from ..adjoints import get_gradient
from ..interrupts import NAMES, Interrupted, catching, check, handled
from ..io import as_checkpoint
from ..state import SimulationError, Trajectory
from .outcome import CONVERGED, FAILED, INTERRUPTED, LIMIT, STATUS, ipopt_outcome, lbfgsb_outcome
from .stages import carry, stage_name, stage_problems

METHODS = ("lbfgsb", "ipopt")
__all__ = ["CONVERGED", "FAILED", "INTERRUPTED", "LIMIT", "METHODS", "Result", "solve",
           "stage_problems"]


@dataclass
class Result:
    """Outcome of :func:`solve` (``x`` are the controls, the best point the search saw).

    ``status`` says how the search ended: 0 converged; 1 a limit (iterations, evaluations,
    ``time_limit``) was reached first; 2 the search failed (a line search found no lower
    point, an IPOPT error); 3 interrupted (Ctrl-C, SIGTERM).  ``success`` is ``status ==
    0`` and ``message`` says in a sentence what happened and, on failure, what to try.
    """

    x: np.ndarray
    fun: float
    jac: np.ndarray
    nit: int
    nfev: int
    success: bool
    status: int
    message: str
    method: str
    gradient: str
    trajectory: Trajectory | None = None
    history: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    breakdown: dict = field(default_factory=dict)
    stages: list = field(default_factory=list)

    @property
    def start(self) -> dict:
        """Objective and keyframe error at the starting controls (of the first stage)."""
        first = self.stages[0] if self.stages else {}
        return {"objective": first.get("start_objective"),
                "keyframe_error": first.get("start_keyframe_error")}

    def summary(self) -> dict:
        """JSON-ready summary (no arrays); ``stages`` has one entry per continuation stage
        (time step, iterations, evaluations, best objective at that step, status, seconds)."""
        return {"fun": self.fun, "nit": self.nit, "nfev": self.nfev, "success": self.success,
                "status": self.status, "status_name": STATUS[self.status],
                "message": self.message, "method": self.method, "gradient": self.gradient,
                "timings": self.timings, "breakdown": self.breakdown, "stages": self.stages,
                "gradient_norm": float(np.linalg.norm(self.jac))}


class _Evaluator:
    """Memoised objective and gradient that tracks the best point and failed simulations.

    ``stage`` is the continuation stage it serves; ``export`` maps its controls to the final
    problem's grid for the checkpoint (an :class:`~.io.Checkpoint` or None)."""

    def __init__(self, problem, gradient, checkpoint, *, stage: int = 0, export=None):
        self.problem, self.gradient = problem, get_gradient(gradient)
        self.checkpoint, self.stage = checkpoint, stage
        self.export = export or (lambda u: u)
        self.nfev = 0
        self.failures = 0
        self.last_failure = ""
        self.last_u = None
        self.best_u, self.best_f, self.best_g = None, np.inf, None
        self.seconds = 0.0
        self.interrupted = None
        self.start = None  # (objective, keyframe error) at the starting controls

    def __call__(self, u):
        u = np.array(u, dtype=float).ravel()
        if self.last_u is not None and np.array_equal(u, self.last_u):
            return self.last
        t = time.perf_counter()
        try:
            check()  # a signal caught by interrupts.catching stops the search here
            f, g = self.gradient(self.problem, u)
        except SimulationError as err:
            # a finite value well above the best lets L-BFGS-B backtrack (with inf it gives
            # up: measured, one iteration and "RELATIVE REDUCTION OF F"); IPOPT rejects it too
            self.failures += 1
            self.last_failure = str(err)
            best = self.best_f if np.isfinite(self.best_f) else 0.0
            f, g = best + 10.0 * (abs(best) + 1.0), np.zeros_like(u)
        except KeyboardInterrupt as err:  # IPOPT would swallow it: remember, then re-raise
            self.interrupted = getattr(err, "signum", signal.SIGINT)
            raise
        self.seconds += time.perf_counter() - t
        self.nfev += 1
        self.last_u, self.last = u, (f, g)
        if f < self.best_f:
            self.best_u, self.best_f, self.best_g = u, f, g
        return f, g

    def record(self, history, start, bar):
        """Append one iteration (at the last evaluated point) to ``history``; the checkpoint
        gets the best controls on the final grid (``u``), their objective at this stage's
        time step (``fun``), the iterations so far (``nit``), the ``stage`` and its
        ``stage_dt``."""
        u, (f, _) = self.last_u, self.last
        control = self.problem.control_cost(u)[0]
        history.append({"iteration": len(history) + 1, "stage": self.stage,
                        "dt": self.problem.dt, "particles": self.problem.model.n,
                        "objective": float(f),
                        "keyframe_error": float(f - control),
                        "control_norm": float(np.linalg.norm(u)),
                        "seconds": time.perf_counter() - start, "nfev": self.nfev})
        if self.checkpoint is not None and self.best_u is not None:
            self.checkpoint.write(self.export(self.best_u), fun=float(self.best_f),
                                  nit=len(history), stage=self.stage,
                                  stage_dt=float(self.problem.dt))
        bar.update(1)
        bar.set_postfix(f=f"{f:.4g}")
        check()


def solve(problem, method: str = "lbfgsb", *, gradient="adjoint", maxiter: int = 200,
          tol: float = 1e-8, u0=None, quiet: bool = False, checkpoint=None,
          options: dict | None = None, continuation=None, resolutions=None,
          time_limit: float | None = None) -> Result:
    """Optimise the problem's controls.

    ``method`` is "lbfgsb" or "ipopt"; ``gradient`` a route name or strategy; ``u0`` the
    starting controls at ``problem.dt`` (default: the problem's guess, else passive);
    ``checkpoint`` a ``.npz`` path (or :class:`~.io.Checkpoint`) that always holds the best
    controls so far (at ``problem.dt``, also during a coarse stage); ``options`` go to the
    underlying solver; ``time_limit`` (seconds, wall clock, over all stages) stops the
    search at the first iteration past it (IPOPT: its ``max_wall_time``) with status 1.

    ``continuation`` (the paper's section 6: optimise at a large time step, then refine) is a
    list of time steps from coarse to fine, e.g. ``[4 * prob.dt, 2 * prob.dt]``; the
    problem's own dt is appended if the list does not end with it.  ``u0``, if given, is
    carried to the first stage's grid.  Each stage solves
    ``problem.resampled(dt)`` from the previous stage's best controls carried to its grid
    (``controls.resample``: the force in newtons stays the same function of time).
    ``maxiter`` applies to each stage.  The result is the last stage's, at ``problem.dt``;
    ``nit``, ``nfev`` and ``timings`` are totals over the stages, every ``history`` record
    names its ``stage`` and ``dt``, and ``stages`` lists per stage its dt, iterations,
    evaluations, best objective (at that dt), status, message and seconds.  An interrupt or
    the time limit during an earlier stage ends the continuation there: the result is that
    stage's best controls resampled to ``problem.dt`` and evaluated there, and its message
    names the stage.

    ``resolutions`` (coarse to fine in space, e.g. a cloth solved on a 12 x 12 mesh, then
    25 x 25, then its own) lists coarser versions of the problem: problems, or dicts of
    build overrides such as ``{"rows": 12, "cols": 12}`` for a problem built from a problem
    file (:meth:`~.problem.ControlProblem.at_resolution`).  Each mesh, coarse to fine, is
    solved in turn (with the ``continuation``'s time steps, if given) from the previous
    mesh's best controls carried to it (:func:`~.transfer.carry_to_mesh`: interpolated on
    the rest mesh, momentum and impulse kept); stages and history records name the mesh's
    ``particles``, and the checkpoint always holds controls of ``problem`` itself.

    A simulation that fails at the starting controls raises :class:`SimulationError`;
    during the search a failing point counts as a failed evaluation.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    if maxiter < 1:
        raise ValueError("maxiter must be at least 1")
    if time_limit is not None and not time_limit > 0:
        raise ValueError(f"time_limit must be a positive number of seconds, got {time_limit}")
    problems = stage_problems(problem, continuation, resolutions)
    strategy = get_gradient(gradient)
    search = _Search(method, maxiter, tol, options or {}, quiet, as_checkpoint(checkpoint),
                     time_limit)
    u = None if u0 is None else carry(problem, problem.controls.check(u0), problems[0])
    stages = []
    for k, p in enumerate(problems):
        ev = _Evaluator(p, strategy, search.checkpoint, stage=k,
                        export=lambda v, p=p: carry(p, v, problem))
        stages.append(search.run(p, ev, p.initial_controls() if u is None else u,
                                 (k, len(problems))))
        if p is problem or stages[-1]["status"] == INTERRUPTED or search.time_up():
            break
        u = carry(p, ev.best_u, problems[k + 1])
    return _result(problem, p, ev, strategy, search, stages, len(problems))


def _result(problem, p, ev, strategy, search, stages, count) -> Result:
    """The Result at ``problem.dt`` from the evaluator ``ev`` of the last stage run (``p``)."""
    status, message = stages[-1]["status"], stages[-1]["message"]
    if p is problem:
        u, fun, jac = ev.best_u, float(ev.best_f), ev.best_g
    else:
        u = carry(p, ev.best_u, problem)
        fun, jac = evaluate_final(problem, strategy, u)
        if status != INTERRUPTED:  # the time limit, maybe reached just as the stage ended
            status = LIMIT
            message = f"time limit reached ({search.time_limit:g} s) before converging"
        message = (f"{message}, in stage {stages[-1]['stage']} of 0..{count - 1} "
                   f"({stage_name(p)}): its best controls, carried to the problem "
                   f"({stage_name(problem)}), kept")
    traj = problem.simulate(u)
    return Result(x=u, fun=fun, jac=jac, nit=sum(s["nit"] for s in stages),
                  nfev=sum(s["nfev"] for s in stages), success=status == CONVERGED,
                  status=status, message=message, method=search.method,
                  gradient=getattr(strategy, "name", type(strategy).__name__),
                  trajectory=traj, history=search.history,
                  timings={"wall_seconds": time.perf_counter() - search.start,
                           "evaluation_seconds": sum(s["evaluation_seconds"] for s in stages),
                           "failed_simulations": sum(s["failed_simulations"] for s in stages),
                           "stage_seconds": [s["seconds"] for s in stages]},
                  breakdown=problem.breakdown(u, traj), stages=stages)


class _Search:
    """What the stages of one :func:`solve` share: the optimizer and its settings, the
    history, the checkpoint and the clock."""

    def __init__(self, method, maxiter, tol, options, quiet, checkpoint, time_limit):
        self.method, self.maxiter, self.tol, self.options = method, maxiter, tol, options
        self.quiet, self.checkpoint, self.time_limit = quiet, checkpoint, time_limit
        self.history, self.start = [], time.perf_counter()
        self.deadline = None if time_limit is None else self.start + time_limit

    def time_up(self) -> bool:
        return self.deadline is not None and time.perf_counter() >= self.deadline

    def run(self, problem, ev, u0, stage) -> dict:
        """One optimizer run from ``u0``: the stage's record (``nit``, ``status``,
        ``message``, ...)."""
        t, first = time.perf_counter(), len(self.history)
        status, message = self._search(problem, ev, u0, stage)
        if status == LIMIT and self.time_up():
            message = f"time limit reached ({self.time_limit:g} s) before converging"
        return {"stage": stage[0], "dt": problem.dt, "steps": problem.steps,
                "particles": problem.model.n,
                "nit": len(self.history) - first, "nfev": ev.nfev, "fun": float(ev.best_f),
                "start_objective": ev.start[0], "start_keyframe_error": ev.start[1],
                "success": status == CONVERGED, "status": status, "message": message,
                "seconds": time.perf_counter() - t, "evaluation_seconds": ev.seconds,
                "failed_simulations": ev.failures}

    def _search(self, problem, ev, u0, stage):
        k, count = stage
        where = "" if count == 1 else f" of stage {k} ({stage_name(problem)})"
        f0, _ = ev(u0)
        ev.start = (float(f0), float(f0 - problem.control_cost(u0)[0]))
        if ev.failures:
            raise SimulationError(f"the simulation fails at the starting controls{where} "
                                  f"({ev.last_failure})"
                                  + ("" if not where else "; start the continuation at a "
                                     "finer dt or mesh" if k == 0 else "; the controls "
                                     "carried from the previous stage fail here: start the "
                                     "continuation at a finer dt or mesh"), 0)
        desc = f"{problem.name} [{self.method}]" + ("" if count == 1 else f" stage {k}/{count - 1}")
        bar = tqdm(total=self.maxiter, disable=self.quiet, desc=desc, leave=False)
        run = _lbfgsb if self.method == "lbfgsb" else _ipopt
        metric = problem.controls.metric(problem.model, problem.dt)
        searched, start = (ev, u0) if metric is None else (_InMetric(ev, metric),
                                                          metric.unsmooth(u0))
        try:
            return run(problem, searched, start, self.maxiter, self.tol, self.options,
                       lambda: ev.record(self.history, self.start, bar), self.deadline)
        except KeyboardInterrupt as err:
            handled()
            signum = getattr(err, "signum", signal.SIGINT)
            who = ("by user (SIGINT)" if signum == signal.SIGINT
                   else f"by {NAMES.get(signum, signum)}")
            return INTERRUPTED, f"interrupted {who}; best result kept"
        finally:
            bar.close()


class _InMetric:
    """The evaluator as the optimizer sees it in a smooth metric: a function of z with
    ``u = S z`` (:mod:`.metrics`), its gradient ``S^T g = S g``; ``best_u`` is the z of the
    best controls.  The evaluator itself keeps working in u (history, checkpoint, best)."""

    def __init__(self, ev, metric):
        self.ev, self.metric = ev, metric

    def __call__(self, z):
        f, g = self.ev(self.metric.smooth(z))
        return f, self.metric.smooth(g)

    @property
    def best_u(self):
        return self.metric.unsmooth(self.ev.best_u)

    @property
    def interrupted(self):
        return self.ev.interrupted


def evaluate_final(problem, strategy, u):
    """Objective and gradient of ``problem`` at the controls ``u`` a search ends on (after a
    continuation stage stopped early, or the last augmented-Lagrangian round); if that is
    interrupted too, the objective alone (gradient NaN)."""
    try:
        f, g = strategy(problem, u)
        return float(f), g
    except KeyboardInterrupt:
        return float(problem.objective(u)), np.full(u.size, np.nan)


class _TimeUp(Exception):
    """Raised from L-BFGS-B's callback past the deadline (scipy lets it through)."""


def _lbfgsb(problem, ev, u0, maxiter, tol, options, on_iteration, deadline):
    opts = {"maxiter": maxiter, "maxfun": 10 * maxiter, "ftol": tol, "gtol": 1e-10,
            "maxcor": 20}
    opts.update(options)
    lb, ub = problem.bounds()
    bounds = list(zip(lb, ub)) if np.isfinite(lb).any() or np.isfinite(ub).any() else None

    def callback(intermediate_result):
        on_iteration()
        if deadline is not None and time.perf_counter() >= deadline:
            raise _TimeUp

    try:
        res = minimize(ev, u0, jac=True, method="L-BFGS-B", bounds=bounds, options=opts,
                       callback=callback)
        status, message = lbfgsb_outcome(res.message, maxiter=opts["maxiter"],
                                         maxfun=opts["maxfun"])
        # a line search that fails after progress restarts from the best point with no
        # curvature memory: its first step is along the steepest descent, so a second
        # failure there means no step lowers phi (a kink, such as the cloth law's at rest
        # length, or round-off); one that fails at the first step leaves the gradient suspect
        if not (status == FAILED and _line_search_failed(res)
                and 0 < res.nit < opts["maxiter"] and res.nfev < opts["maxfun"]):
            return status, message
        opts["maxiter"] -= res.nit
        opts["maxfun"] -= res.nfev
        again = minimize(ev, ev.best_u, jac=True, method="L-BFGS-B", bounds=bounds,
                         options=opts, callback=callback)
    except _TimeUp:
        return LIMIT, "time limit reached before converging"
    if _line_search_failed(again) and again.nit == 0:
        return CONVERGED, ("converged: no step along the steepest descent lowers the "
                           "objective (the line search failed, and again from the best point "
                           "with fresh curvature memory): a kink of the objective or its "
                           f"round-off floor [L-BFGS-B: {again.message}]")
    return lbfgsb_outcome(again.message, maxiter=maxiter, maxfun=opts["maxfun"])


def _line_search_failed(res) -> bool:
    return str(res.message).upper().startswith("ABNORMAL")


class _Objective(ca.Callback):
    """phi(u) for IPOPT, with the gradient from the chosen strategy as its Jacobian."""

    def __init__(self, ev, n):
        ca.Callback.__init__(self)
        self.ev, self.n = ev, n
        self.construct("phi", {"enable_fd": False})

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        return [self.ev(np.asarray(arg[0]).ravel())[0]]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _Gradient(self.ev, self.n, name, opts)  # IPOPT needs it kept alive
        return self._jac


class _Gradient(ca.Callback):
    def __init__(self, ev, n, name, opts):
        ca.Callback.__init__(self)
        self.ev, self.n = ev, n
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return 2

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.n, 1) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(1, self.n)

    def eval(self, arg):
        return [self.ev(np.asarray(arg[0]).ravel())[1].reshape(1, -1)]


class _Iteration(ca.Callback):
    """IPOPT's per-iteration hook: records history; returns 1 to stop on Ctrl-C."""

    def __init__(self, n, on_iteration):
        ca.Callback.__init__(self)
        self.n, self.on_iteration, self.interrupted, self.count = n, on_iteration, None, 0
        self.construct("iteration", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        if name in ("x", "lam_x"):
            return ca.Sparsity.dense(self.n, 1)
        if name in ("f",):
            return ca.Sparsity.dense(1, 1)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        try:
            self.count += 1
            if self.count > 1:  # IPOPT reports iteration 0, the start, first
                self.on_iteration()
        except KeyboardInterrupt as err:
            self.interrupted = getattr(err, "signum", signal.SIGINT)
            return [1]
        return [0]


def _ipopt(problem, ev, u0, maxiter, tol, options, on_iteration, deadline):
    n = problem.size
    phi = _Objective(ev, n)
    it = _Iteration(n, on_iteration)
    U = ca.MX.sym("u", n)
    ipopt = {"hessian_approximation": "limited-memory", "max_iter": maxiter, "tol": tol,
             "print_level": 0, "sb": "yes", "limited_memory_max_history": 20}
    if deadline is not None:
        ipopt["max_wall_time"] = max(deadline - time.perf_counter(), 1e-3)
    ipopt.update(options)
    solver = ca.nlpsol("keyframe", "ipopt", {"x": U, "f": phi(U)},
                       {"ipopt": ipopt, "print_time": False, "iteration_callback": it,
                        "error_on_fail": False})
    solver._keep = (phi, it)  # Callbacks must outlive the solver
    lb, ub = problem.bounds()
    # an interrupt CasADi catches inside IPOPT ends it as NonIpopt_Exception_Thrown: the
    # handler's log, the evaluator and the iteration hook say it was one
    with catching(signal.SIGINT) as caught:
        solver(x0=u0, lbx=lb, ubx=ub)
    signum = caught.signum or ev.interrupted or it.interrupted
    if signum:
        raise Interrupted(signum)
    return ipopt_outcome(solver.stats().get("return_status", "unknown"),
                         maxiter=ipopt["max_iter"])
