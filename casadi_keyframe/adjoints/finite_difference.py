"""The "fd" route: central differences, one control at a time; a slow, independent witness
for tests and audits that needs no derivative code.  Not exact (its error is the step's);
it runs no backward loop: a non-finite gradient is refused."""
from __future__ import annotations

import numpy as np

from ..health import check_finite
from .base import Evaluation, Route, bare


class FiniteDifference(Route):
    """Central differences with step ``h``: ``(phi(u + h e_i) - phi(u - h e_i)) / 2h``."""

    name = "fd"
    exact = False
    help = "finite differences"

    def __init__(self, h: float = 1e-6):
        self.h = h

    def evaluate(self, problem, u) -> Evaluation:
        grad = np.empty_like(u)
        for i in range(u.size):
            grad[i] = self.directional(problem, u, _unit(u.size, i))
        check_finite(self, grad, problem)
        run = problem.simulate(u, records=False)  # the objective, as problem.objective says
        value = problem.state_cost(run, gradient=False)[0] + problem.control_cost(u)[0]
        return Evaluation(value, grad, bare(run))

    def directional(self, problem, u, direction) -> float:
        """Central difference of phi along ``direction``."""
        h = self.h
        return (problem.objective(u + h * direction) - problem.objective(u - h * direction)) / (2 * h)


def _unit(n, i):
    e = np.zeros(n)
    e[i] = 1.0
    return e
