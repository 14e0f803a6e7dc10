"""The gradient routes by name, in one place: ``gradient=`` and ``--gradient`` take these
names, and :func:`route_help` writes the command line's help from them.  A new route is its
own file (a :class:`~.base.Route` with its facts) and one entry here."""
from __future__ import annotations

import warnings

from .adjoint import Adjoint
from .base import Evaluation, Route
from .casadi_reverse import CasADiReverse
from .exact import Exact
from .finite_difference import FiniteDifference
from .swapped import Swapped

GRADIENTS = {route.name: route for route in (
    Adjoint,
    Swapped,
    CasADiReverse,
    FiniteDifference,
)}
DEPRECATED = {"exact": Exact}  # old names: each class names the route it became
ROUTES = (*GRADIENTS, *DEPRECATED)  # every name get_gradient takes
DEFAULT = Adjoint  # exact at a forward pass's cost: the default, where refusals send users,
#                    what the health report measures the other routes against


def get_gradient(gradient=None) -> Route:
    """The route ``gradient`` names (None: :data:`DEFAULT`), or the route object itself; a
    plain callable ``f(problem, u) -> (phi, grad)`` is made a route (:class:`Strategy`)."""
    if gradient is None:
        gradient = DEFAULT.name
    if isinstance(gradient, str):
        if gradient in DEPRECATED:
            old = DEPRECATED[gradient]
            warnings.warn(old.deprecation, DeprecationWarning, stacklevel=3)
            return old.replaced_by()
        if gradient not in GRADIENTS:
            raise ValueError(f"unknown gradient {gradient!r}; choose one of {sorted(GRADIENTS)}")
        return GRADIENTS[gradient]()
    if isinstance(gradient, Route):
        return gradient
    if not callable(gradient):
        raise TypeError("gradient must be a name or a callable strategy")
    return Strategy(gradient)


class Strategy(Route):
    """A plain callable ``f(problem, u) -> (phi, grad)`` as a route: its evaluation has no run
    and no growth (the function keeps them to itself); its name is the function's ``name``
    attribute, else its type's."""

    def __init__(self, function):
        self.function = function
        self.name = getattr(function, "name", type(function).__name__)

    def evaluate(self, problem, u) -> Evaluation:
        value, gradient = self.function(problem, u)
        return Evaluation(value, gradient)


def route_help(lead: str = "gradient route") -> str:
    """The command line's help for ``--gradient``: ``lead``, the default, each route's
    phrase and the deprecated names."""
    routes = ", ".join(f"'{name}' {route.help}" for name, route in GRADIENTS.items())
    old = "; ".join(f"'{name}' is a deprecated name of '{route.replaced_by.name}'"
                    for name, route in DEPRECATED.items())
    return (f"{lead} (default: the problem's SOLVE, else '{DEFAULT.name}'): {routes}"
            + (f" ({old})" if old else ""))
