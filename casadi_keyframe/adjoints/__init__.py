"""Gradient routes, passed as ``gradient=`` (an object or its name); each owns its backward
pass, returns what it computed whole (``route.evaluate(problem, u)`` ->
:class:`~.base.Evaluation`: value, gradient, run, backward growth; ``route(problem, u)`` ->
``(phi, dphi/du)`` is the short form) and carries its own facts
(:class:`~.base.Route`: exact or approximate, growth bound, known limits, likely cause of a
refusal, help line), which the health guard, the health report, a search's result and the
command line ask instead of branching on its name.

* :class:`Adjoint` ("adjoint"): exact; the hand-written discrete adjoint of the scheme.
* :class:`Swapped` ("swapped"): APPROXIMATE; the paper's integrator-swapping adjoint of
  linearized backward Euler (eqs. 13-15).
* :class:`CasADiReverse` ("casadi"): exact, the reference; CasADi reverse mode through the
  unrolled symbolic simulation; for small systems.
* :class:`FiniteDifference` ("fd"): central differences; a slow, independent witness.

"exact" is a deprecated name of "casadi".  The routes by name: :mod:`.registry`.
"""
from .adjoint import Adjoint
from .base import Evaluation, Route
from .casadi_reverse import CasADiReverse, step_parameters, unrolled_objective
from .exact import Exact
from .finite_difference import FiniteDifference
from .registry import DEFAULT, DEPRECATED, GRADIENTS, ROUTES, Strategy, get_gradient, route_help
from .swapped import Swapped

__all__ = ["DEFAULT", "DEPRECATED", "GRADIENTS", "ROUTES", "Adjoint", "CasADiReverse",
           "Evaluation", "Exact", "FiniteDifference", "Route", "Strategy", "Swapped",
           "get_gradient", "route_help", "step_parameters", "unrolled_objective"]
