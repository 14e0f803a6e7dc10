"""Optimizers: L-BFGS-B (scipy) and IPOPT (CasADi nlpsol fed by a Callback).

Both return a :class:`Result` in scipy's vocabulary plus the trajectory, a per-iteration
history and timings.  Ctrl-C stops the solve and returns the best controls seen so far; with
``checkpoint=`` that best is also written to disk at every iteration.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.optimize import minimize
from tqdm.auto import tqdm

from .gradients import get_gradient
from .trajectory import SimulationError, Trajectory

METHODS = ("lbfgsb", "ipopt")


@dataclass
class Result:
    """Outcome of :func:`solve` (``x`` are the controls)."""

    x: np.ndarray
    fun: float
    jac: np.ndarray
    nit: int
    nfev: int
    success: bool
    message: str
    method: str
    gradient: str
    trajectory: Trajectory | None = None
    history: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    breakdown: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-ready summary (no arrays)."""
        return {"fun": self.fun, "nit": self.nit, "nfev": self.nfev, "success": self.success,
                "message": self.message, "method": self.method, "gradient": self.gradient,
                "timings": self.timings, "breakdown": self.breakdown,
                "gradient_norm": float(np.linalg.norm(self.jac))}


class _Evaluator:
    """Memoised objective and gradient that tracks the best point and failed simulations."""

    def __init__(self, problem, gradient, checkpoint):
        self.problem, self.gradient = problem, get_gradient(gradient)
        self.checkpoint = checkpoint
        self.nfev = 0
        self.failures = 0
        self.last_u = None
        self.best_u, self.best_f, self.best_g = None, np.inf, None
        self.seconds = 0.0
        self.interrupted = False

    def __call__(self, u):
        u = np.array(u, dtype=float).ravel()
        if self.last_u is not None and np.array_equal(u, self.last_u):
            return self.last
        t = time.perf_counter()
        try:
            f, g = self.gradient(self.problem, u)
        except SimulationError:
            self.failures += 1
            f, g = np.inf, np.zeros_like(u)
        except KeyboardInterrupt:  # IPOPT would swallow it: remember, then re-raise
            self.interrupted = True
            raise
        self.seconds += time.perf_counter() - t
        self.nfev += 1
        self.last_u, self.last = u, (f, g)
        if f < self.best_f:
            self.best_u, self.best_f, self.best_g = u, f, g
        return f, g

    def record(self, history, start, bar):
        """Append one iteration (at the last evaluated point) to ``history``."""
        u, (f, _) = self.last_u, self.last
        control = self.problem.control_cost(u)[0]
        history.append({"iteration": len(history) + 1, "objective": float(f),
                        "keyframe_error": float(f - control), "control_norm": float(np.linalg.norm(u)),
                        "seconds": time.perf_counter() - start, "nfev": self.nfev})
        if self.checkpoint is not None and self.best_u is not None:
            np.savez(self.checkpoint, u=self.best_u, fun=self.best_f, nit=len(history))
        bar.update(1)
        bar.set_postfix(f=f"{f:.4g}")


def solve(problem, method: str = "lbfgsb", *, gradient="adjoint", maxiter: int = 200,
          tol: float = 1e-8, u0=None, quiet: bool = False, checkpoint=None,
          options: dict | None = None) -> Result:
    """Optimise the problem's controls.

    ``method`` is "lbfgsb" or "ipopt"; ``gradient`` a route name or strategy; ``u0`` the
    starting controls (default: passive); ``checkpoint`` a ``.npz`` path that always holds
    the best controls so far; ``options`` go to the underlying solver.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    if maxiter < 1:
        raise ValueError("maxiter must be at least 1")
    u0 = problem.initial_controls() if u0 is None else problem.controls.check(u0)
    ev = _Evaluator(problem, gradient, checkpoint)
    f0, _ = ev(u0)
    if not np.isfinite(f0):
        raise SimulationError("the simulation fails at the starting controls", 0)
    start = time.perf_counter()
    history: list = []
    bar = tqdm(total=maxiter, disable=quiet, desc=f"{problem.name} [{method}]", leave=False)
    run = _lbfgsb if method == "lbfgsb" else _ipopt
    try:
        nit, success, message = run(problem, ev, u0, maxiter, tol, options or {},
                                    lambda: ev.record(history, start, bar))
    except KeyboardInterrupt:
        nit, success, message = len(history), False, "interrupted by user; best result kept"
    finally:
        bar.close()
    wall = time.perf_counter() - start
    u = ev.best_u
    traj = problem.simulate(u)
    return Result(x=u, fun=float(ev.best_f), jac=ev.best_g, nit=nit, nfev=ev.nfev,
                  success=bool(success), message=message, method=method,
                  gradient=getattr(ev.gradient, "name", type(ev.gradient).__name__),
                  trajectory=traj, history=history,
                  timings={"wall_seconds": wall, "evaluation_seconds": ev.seconds,
                           "failed_simulations": ev.failures},
                  breakdown=problem.breakdown(u, traj))


def _lbfgsb(problem, ev, u0, maxiter, tol, options, on_iteration):
    opts = {"maxiter": maxiter, "maxfun": 10 * maxiter, "ftol": tol, "gtol": 1e-10,
            "maxcor": 20}
    opts.update(options)
    lb, ub = problem.bounds()
    bounds = list(zip(lb, ub)) if np.isfinite(lb).any() or np.isfinite(ub).any() else None
    res = minimize(ev, u0, jac=True, method="L-BFGS-B", bounds=bounds, options=opts,
                   callback=lambda *_: on_iteration())
    return int(res.nit), bool(res.success), str(res.message)


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
        self.n, self.on_iteration, self.interrupted, self.count = n, on_iteration, False, 0
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
        except KeyboardInterrupt:
            self.interrupted = True
            return [1]
        return [0]


def _ipopt(problem, ev, u0, maxiter, tol, options, on_iteration):
    n = problem.size
    phi = _Objective(ev, n)
    it = _Iteration(n, on_iteration)
    U = ca.MX.sym("u", n)
    ipopt = {"hessian_approximation": "limited-memory", "max_iter": maxiter, "tol": tol,
             "print_level": 0, "sb": "yes", "limited_memory_max_history": 20}
    ipopt.update(options)
    solver = ca.nlpsol("keyframe", "ipopt", {"x": U, "f": phi(U)},
                       {"ipopt": ipopt, "print_time": False, "iteration_callback": it,
                        "error_on_fail": False})
    solver._keep = (phi, it)  # Callbacks must outlive the solver
    lb, ub = problem.bounds()
    solver(x0=u0, lbx=lb, ubx=ub)
    stats = solver.stats()
    status = stats.get("return_status", "unknown")
    if it.interrupted or ev.interrupted:
        raise KeyboardInterrupt
    success = bool(stats.get("success", False))
    return int(stats.get("iter_count", it.count - 1)), success, status
