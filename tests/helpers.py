"""What several test files share: a small flock with every objective term, a gradient
route that acts like Ctrl-C, the exact routes' agreement with CasADi, and a slope against
the forward pass's stable central differences.  Imported as ``from helpers import ...`` (pytest puts this folder
on the path)."""
import numpy as np
import pytest

from casadi_keyframe import (Adjoint, CenterOfMassKeyframe, ControlProblem, ParticleKeyframe,
                             RegionTarget, Smoothness, StateKeyframe, StepForces)
from casadi_keyframe.integrators import SymplecticEuler
from casadi_keyframe.models import FlockModel, FlockParams, wander_forces
from casadi_keyframe.shapes import Disc, cross, square


def small_flock(cutoff="smooth", *, n=8, steps=30, dt=0.1, dim=2, controls=None, seed=0):
    """8 agents, 30 steps, unequal masses, drag, wander and every objective term active."""
    rng = np.random.default_rng(seed)
    model = FlockModel(rng.uniform(0.5, 2.0, n), dim, FlockParams(cutoff=cutoff, drag=0.1))
    x0 = rng.uniform(0, 3, (n, dim))
    v0 = rng.standard_normal((n, dim))
    target = rng.uniform(0, 3, (n, dim))
    obj = (StateKeyframe(steps // 3, x=target, v=np.zeros((n, dim)), velocity_weight=0.3)
           + ParticleKeyframe(2 * steps // 3, [1, 3], x=[[5] * dim, [6] * dim])
           + CenterOfMassKeyframe(steps // 2, x=[3] * dim, v=[1] + [0] * (dim - 1))
           + RegionTarget(steps, cross((4, 4), 3, 1), weight=2.0, margin=0.1)
           + RegionTarget(steps - 5, square((2, 2), 1))
           + RegionTarget(steps - 8, Disc((1, 1), 0.5))
           + Smoothness(0.01, temporal=0.01))
    return ControlProblem(model=model, integrator=SymplecticEuler(), x0=x0, v0=v0, steps=steps,
                          dt=dt, controls=controls or StepForces(), objective=obj,
                          external=wander_forces(steps, n, dim, strength=0.3, seed=seed + 1),
                          name="small_flock")


class InterruptAfter(Adjoint):
    """Acts like Ctrl-C after a number of gradient evaluations (and at every one after)."""

    def __init__(self, calls):
        self.calls = calls

    def evaluate(self, problem, u):
        self.calls -= 1
        if self.calls < 0:
            raise KeyboardInterrupt
        return super().evaluate(problem, u)


def assert_exact_routes(prob, u):
    """The hand adjoint and the tangent pass agree with CasADi reverse mode at u (to 1e-8);
    returns ``(g, d)``: the adjoint's gradient and the random direction the tangent took."""
    f, g = prob.objective_and_gradient(u, "adjoint")
    f_ref, g_ref = prob.objective_and_gradient(u, "casadi")
    assert f == pytest.approx(f_ref, rel=1e-10)
    assert np.linalg.norm(g - g_ref) <= 1e-8 * np.linalg.norm(g_ref)
    d = np.random.default_rng(1).standard_normal(prob.size)
    assert prob.directional_derivative(u, d) == pytest.approx(g_ref @ d, rel=1e-8)
    return g, d


def assert_forward_derivative(prob, u, slope, d, tolerance=1e-6):
    """``slope`` (a route's ``g . d``) is the derivative of the forward pass along ``d``: the
    central difference of ``simulate``, stable over three decades of h, meets it within
    ``tolerance``; returns the :class:`StableDifference`."""
    from casadi_keyframe.studies.forward_differences import stable_difference
    size = np.linalg.norm(d)
    fd = stable_difference(prob, u, d / size)
    slope = slope / size
    assert fd.stable, f"central differences not stable over three decades: {fd.describe()}"
    assert fd.error(slope) <= tolerance, (fd.error(slope), fd.describe())
    return fd
