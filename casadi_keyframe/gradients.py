"""Gradient strategies, passed as ``gradient=`` (an object or its name).

Each is called as ``strategy(problem, u) -> (phi, dphi/du)``.

* :class:`Adjoint` ("adjoint"): the integrator's hand-written adjoint.  Exact for symplectic
  Euler (eq. 8); for cloth it is the integrator-swapping approximation (eqs. 13-15).
* :class:`Exact` ("exact"): CasADi reverse mode through the unrolled symbolic simulation
  (all pairs, every step in the graph).  Exact for the scheme simulated; for small systems.
* :class:`FiniteDifference` ("fd"): central differences, one coordinate at a time; a slow,
  independent witness for tests.
"""
from __future__ import annotations

import casadi as ca
import numpy as np


class Adjoint:
    """Forward simulation, then the integrator's adjoint backwards in time."""

    name = "adjoint"

    def __call__(self, problem, u):
        traj = problem.simulate(u)
        value, gx, gv = problem.state_cost(traj)
        g_ext, _, g_v0 = problem.integrator.adjoint(problem.model, traj, gx, gv)
        c_val, c_grad = problem.control_cost(u)
        return value + c_val, problem.controls.pullback(g_ext, g_v0) + c_grad


class Exact:
    """CasADi reverse mode through the unrolled simulation; compiled once per problem."""

    name = "exact"

    def function(self, problem) -> ca.Function:
        if problem._exact is None:
            U = ca.MX.sym("U", problem.size)
            J = problem.symbolic_objective(U)
            problem._exact = ca.Function("exact_gradient", [U], [J, ca.gradient(J, U)])
        return problem._exact

    def __call__(self, problem, u):
        val, grad = self.function(problem)(u)
        return float(val), np.asarray(grad).ravel()


class FiniteDifference:
    """Central differences with step ``h``: ``(phi(u + h e_i) - phi(u - h e_i)) / 2h``."""

    name = "fd"

    def __init__(self, h: float = 1e-6):
        self.h = h

    def __call__(self, problem, u):
        grad = np.empty_like(u)
        for i in range(u.size):
            grad[i] = self.directional(problem, u, _unit(u.size, i))
        return problem.objective(u), grad

    def directional(self, problem, u, direction) -> float:
        """Central difference of phi along ``direction``."""
        h = self.h
        return (problem.objective(u + h * direction) - problem.objective(u - h * direction)) / (2 * h)


def _unit(n, i):
    e = np.zeros(n)
    e[i] = 1.0
    return e


GRADIENTS = {"adjoint": Adjoint, "exact": Exact, "fd": FiniteDifference}


def get_gradient(gradient):
    """A strategy object from a name or an object."""
    if isinstance(gradient, str):
        if gradient not in GRADIENTS:
            raise ValueError(f"unknown gradient {gradient!r}; choose one of {sorted(GRADIENTS)}")
        return GRADIENTS[gradient]()
    if not callable(gradient):
        raise TypeError("gradient must be a name or a callable strategy")
    return gradient
