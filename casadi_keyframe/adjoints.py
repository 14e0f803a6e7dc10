"""Gradient strategies, passed as ``gradient=`` (an object or its name); each owns its
backward pass and is called as ``strategy(problem, u) -> (phi, dphi/du)``.

* :class:`Adjoint` ("adjoint"): exact; the discrete adjoint of the scheme simulated, eq. (5)
  with the integrator's hand-written backward step (symplectic Euler's eq. 8; the exact
  adjoint of linearized backward Euler; full backward Euler's adjoint).
* :class:`Swapped` ("swapped"): APPROXIMATE; the paper's integrator-swapping adjoint of
  linearized backward Euler (eqs. 13-15).
* :class:`CasADiReverse` ("casadi"): exact, the reference; CasADi reverse mode through the
  unrolled symbolic simulation (all pairs, every step in the graph); for small systems.
* :class:`FiniteDifference` ("fd"): central differences, one coordinate at a time; a slow,
  independent witness for tests.

"exact" is a deprecated name of "casadi".

Every strategy watches its gradient (:mod:`casadi_keyframe.health`): "adjoint" and
"swapped" watch their backward pass and raise :class:`~casadi_keyframe.health.GradientError`
when it grows past the route's bound (:func:`~casadi_keyframe.health.growth_bound`) or
overflows (``guard=False`` only records); each keeps the last pass's
:class:`~casadi_keyframe.health.Growth` in ``growth``; "casadi" and "fd" refuse a non-finite
gradient.
"""
from __future__ import annotations

import warnings
import weakref

import casadi as ca
import numpy as np

from .health import BackwardWatch, check_finite, growth_bound, warn_route_limits
from .simulate import backward


class Adjoint:
    """Exact: the discrete adjoint of the simulated scheme, by its hand-written backward step.

    ``guard`` (default): the evaluation fails with a GradientError if the backward pass
    grows past ``bound`` or overflows; without, its growth is only recorded (``growth``)."""

    name = "adjoint"
    exact = True
    guard = True  # class defaults (subclasses may skip __init__)
    bound = growth_bound("adjoint")
    growth = None  # the last backward pass's health.Growth

    def __init__(self, *, guard: bool = True, bound: float | None = None):
        self.guard = guard
        self.bound = growth_bound(self.name) if bound is None else bound

    def backward_step(self, integrator):
        """The integrator's backward step this strategy runs in eq. (5)."""
        return integrator.step_vjp

    def __call__(self, problem, u):
        self.growth = None
        step_vjp = self.backward_step(problem.integrator)
        traj = problem.simulate(u)
        value, gx, gv = problem.state_cost(traj)
        watch = BackwardWatch(self.name, problem, guard=self.guard, bound=self.bound)
        try:
            g_ext, g0 = backward(problem.integrator, problem.model, traj, gx, gv,
                                 step_vjp=step_vjp, watch=watch)
        finally:
            self.growth = watch.result()
            problem.integrator.release(traj)
        c_val, c_grad = problem.control_cost(u)
        grad = problem.controls.pullback(g_ext, g0.v) + c_grad
        if self.guard:
            check_finite(self.name, grad, problem)
        return value + c_val, grad


class Swapped(Adjoint):
    """APPROXIMATE: the paper's integrator-swapping adjoint (eqs. 13-15), the adjoint of full
    backward Euler run on a linearized backward Euler trajectory; its error is measured
    against "adjoint" or "casadi" in the gradient-accuracy study."""

    name = "swapped"
    exact = False
    bound = growth_bound("swapped")

    def backward_step(self, integrator):
        step = getattr(integrator, "swapped_step_vjp", None)
        if step is None:
            raise ValueError(
                f"gradient='swapped' is the paper's approximate adjoint of linearized backward "
                f"Euler (cloth); {integrator.name} has none: use gradient='adjoint', its "
                "exact adjoint")
        return step

    def __call__(self, problem, u):
        warn_route_limits(self.name, problem.model)  # once per model
        return super().__call__(problem, u)


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


def step_parameters(problem, u) -> np.ndarray:
    """Every step's symbolic parameters for controls u: what depends on time and, for a
    scheme that decides something per step (the contacts a step holds), what the numeric
    simulation decided, so the unrolled graph follows the path actually simulated."""
    integrator, model, dt = problem.integrator, problem.model, problem.dt
    records = problem.simulate(u).records if integrator.decides_per_step(model) else None
    return np.concatenate([integrator.step_parameters(model, n * dt, dt,
                                                      None if records is None else records[n])
                           for n in range(problem.steps)] or [np.zeros(0)])


class CasADiReverse:
    """Exact, the reference: CasADi reverse mode through the unrolled simulation of the path
    the numeric simulation takes (the contacts it holds, for a cloth that holds them); its
    Function is built once per problem and kept while the problem lives."""

    name = "casadi"
    exact = True
    growth = None  # no backward loop of its own to watch: a non-finite gradient is refused
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

    def __call__(self, problem, u):
        val, grad = self.function(problem)(u, step_parameters(problem, u))
        grad = np.asarray(grad).ravel()
        check_finite(self.name, grad, problem)
        return float(val), grad


class Exact(CasADiReverse):
    """Deprecated name of :class:`CasADiReverse` ("casadi")."""

    def __init__(self):
        warnings.warn(DEPRECATED_EXACT, DeprecationWarning, stacklevel=2)


DEPRECATED_EXACT = ("gradient 'exact' is deprecated: it is CasADi reverse mode, now named "
                    "'casadi' (the hand-written exact adjoint is 'adjoint')")


class FiniteDifference:
    """Central differences with step ``h``: ``(phi(u + h e_i) - phi(u - h e_i)) / 2h``."""

    name = "fd"
    exact = False
    growth = None

    def __init__(self, h: float = 1e-6):
        self.h = h

    def __call__(self, problem, u):
        grad = np.empty_like(u)
        for i in range(u.size):
            grad[i] = self.directional(problem, u, _unit(u.size, i))
        check_finite(self.name, grad, problem)
        return problem.objective(u), grad

    def directional(self, problem, u, direction) -> float:
        """Central difference of phi along ``direction``."""
        h = self.h
        return (problem.objective(u + h * direction) - problem.objective(u - h * direction)) / (2 * h)


def _unit(n, i):
    e = np.zeros(n)
    e[i] = 1.0
    return e


GRADIENTS = {"adjoint": Adjoint, "swapped": Swapped, "casadi": CasADiReverse,
             "fd": FiniteDifference}
ROUTES = (*GRADIENTS, "exact")  # every name get_gradient takes ("exact": deprecated)


def get_gradient(gradient):
    """A strategy object from a name or an object."""
    if isinstance(gradient, str):
        if gradient == "exact":
            warnings.warn(DEPRECATED_EXACT, DeprecationWarning, stacklevel=3)
            return CasADiReverse()
        if gradient not in GRADIENTS:
            raise ValueError(f"unknown gradient {gradient!r}; choose one of {sorted(GRADIENTS)}")
        return GRADIENTS[gradient]()
    if not callable(gradient):
        raise TypeError("gradient must be a name or a callable strategy")
    return gradient
