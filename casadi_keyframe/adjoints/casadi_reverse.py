"""The "casadi" route: exact, the reference; CasADi reverse mode through the unrolled symbolic
simulation (every step in one graph, all pairs); several forward passes and much memory, so
for small systems.  It runs no backward loop of its own: a non-finite gradient is refused."""
from __future__ import annotations

import weakref

import casadi as ca
import numpy as np

from ..health import check_finite
from .base import Evaluation, Route, bare


def unrolled_objective(problem, U, P):
    """The whole objective as an MX expression of the controls U, through the unrolled
    symbolic simulation (the integrator's ``symbolic_step`` at every step); ``P`` holds every
    step's parameters S, one after another (:func:`step_parameters`)."""
    forces, dv0 = problem.controls.symbolic(U)
    X = ca.DM(problem.x0.T)
    V = ca.DM(problem.v0.T) + (dv0 if dv0 is not None else 0)
    step = problem.integrator.symbolic_step(problem.model)
    size = step.size1_in(4)
    by_frame: dict[int, list] = {}
    for t in problem.objective_terms.state_terms:
        by_frame.setdefault(t.frame, []).append(t)
    J = 0
    for n in range(problem.steps + 1):
        for t in by_frame.get(n, []):
            J += t.symbolic(X, V)
        if n > 0:
            for t in problem.objective_terms.trajectory_terms:
                J += t.symbolic(X, V, problem.dt, n)
        if n < problem.steps:
            E = ca.DM(problem.external[n].T)
            if forces is not None:
                E = E + forces[n]
            X, V = step(X, V, E, problem.dt, P[n * size:(n + 1) * size])
    return J + problem.control_expression(U)


def step_parameters(problem, u, run=None) -> np.ndarray:
    """Every step's symbolic parameters for controls u: what depends on time and, for a
    scheme that decides something per step (the contacts a step holds), what the numeric
    simulation decided (``run``, the run of ``u`` with its records, simulated if not given),
    so the unrolled graph follows the path actually simulated."""
    integrator, model, dt = problem.integrator, problem.model, problem.dt
    records = None
    if integrator.decides_per_step(model):
        records = (problem.simulate(u) if run is None else run).records
    return np.concatenate([integrator.step_parameters(model, n * dt, dt,
                                                      None if records is None else records[n])
                           for n in range(problem.steps)] or [np.zeros(0)])


class CasADiReverse(Route):
    """Exact, the reference: CasADi reverse mode through the unrolled simulation of the path
    the numeric simulation takes (the contacts it holds, for a cloth that holds them); its
    Function is built once per problem and kept while the problem lives."""

    name = "casadi"
    exact = True
    help = "CasADi reverse mode (small systems)"
    _functions: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()

    def function(self, problem) -> ca.Function:
        fn = self._functions.get(problem)
        if fn is None:
            U = ca.MX.sym("U", problem.size)
            step = problem.integrator.symbolic_step(problem.model)
            P = ca.MX.sym("P", step.size1_in(4) * problem.steps)
            J = unrolled_objective(problem, U, P)
            fn = self._functions[problem] = ca.Function("casadi_gradient", [U, P],
                                                        [J, ca.gradient(J, U)])
        return fn

    def evaluate(self, problem, u) -> Evaluation:
        """Its gradient, with the run it simulated where the model decides per step (none
        otherwise: the graph needs no run)."""
        decides = problem.integrator.decides_per_step(problem.model)
        run = problem.simulate(u) if decides else None
        val, grad = self.function(problem)(u, step_parameters(problem, u, run))
        grad = np.asarray(grad).ravel()
        check_finite(self, grad, problem)
        return Evaluation(float(val), grad, None if run is None else bare(run))
