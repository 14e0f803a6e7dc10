"""Interaction families as units: a force law written as one class (here a test-only tether,
each particle pulled towards an anchor that moves with time, and a pair law that attracts
particles) and given to a cloth as one list entry takes part in the step, its exact
derivatives and the CasADi reference without any other change."""
import casadi as ca
import numpy as np
import pytest
from helpers import assert_exact_routes

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.kernels import interaction_kernels
from casadi_keyframe.models import (ClothModel, Interaction, PairInteraction,
                                    ParticleInteraction, Plane)


class Tether(ParticleInteraction):
    """``f = -k (x - a(t)) - c v``, the anchor ``a(t) = a0 + t w``: a particle law with
    time-dependent geometry."""

    name = "tether"

    def __init__(self, n, stiffness, damping, anchor, drift):
        x, v, a = ca.SX.sym("x", 3), ca.SX.sym("v", 3), ca.SX.sym("a", 3)
        gains = ca.SX.sym("gains", 2)
        force = -gains[0] * (x - a) * ca.dot(x - a, x - a) - gains[1] * v  # nonlinear in x
        super().__init__(interaction_kernels("tether", x, v, [a, gains], force), n, None)
        self.gains, self.anchor, self.drift = np.array([stiffness, damping]), anchor, drift

    def columns(self, t):
        a = np.asarray(self.anchor) + t * np.asarray(self.drift)
        return [np.broadcast_to(a, (self.n, 3)), np.broadcast_to(self.gains, (self.n, 2))]

    def parameters(self, t):
        return np.asarray(self.anchor) + t * np.asarray(self.drift)

    def symbolic_columns(self, S, decisions=None):
        return [S, ca.DM(self.gains)]


class Attraction(PairInteraction):
    """``f_i = k d |d|^2``: every listed pair pulls together, a pair law over fixed pairs."""

    name = "attraction"
    role = "internal"

    def __init__(self, n, pairs, strength):
        d, dv, k = ca.SX.sym("d", 3), ca.SX.sym("dv", 3), ca.SX.sym("k")
        super().__init__(interaction_kernels("attraction", d, dv, [k], k * d * ca.dot(d, d)),
                         n, None)
        self.ij = (np.asarray(pairs[0], np.intp), np.asarray(pairs[1], np.intp))
        self.k = np.full((self.ij[0].size, 1), strength)

    def pairs(self, found):
        return self.ij

    def pair_parameters(self, i, j, found=None):
        return [self.k]

    def all_pairs(self):
        return self.ij


def problem(families, steps=6, dt=1 / 30):
    model = ClothModel.grid(4, 4, pinned=[0], colliders=[Plane((0, 0, -1.0))],
                            families=families)
    x0 = model.rest_positions
    objective = (StateKeyframe(steps, x=x0 + [0.1, 0.2, 0.05], v=0 * x0)
                 + Smoothness(1e-4))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=np.zeros_like(x0), steps=steps, dt=dt, controls=StepForces(),
                          objective=objective)


def families():
    return [Tether(16, 30.0, 0.2, (0.5, 0.3, -0.5), (0.0, 0.5, 0.0)),
            Attraction(16, ([1, 5, 10], [15, 12, 3]), 40.0)]


def test_a_new_family_changes_the_motion_and_its_gradient_is_exact():
    with_them, without = problem(families()), problem([])
    assert all(isinstance(f, Interaction) for f in with_them.model.families)
    assert [f.name for f in with_them.model.families][-2:] == ["tether", "attraction"]
    u = 0.05 * np.random.default_rng(0).standard_normal(with_them.size)
    moved = np.abs(with_them.simulate(u).x[-1] - without.simulate(u).x[-1]).max()
    assert moved > 0.01
    assert_exact_routes(with_them, u)


def test_a_family_s_forces_can_be_asked_for_by_role():
    prob = problem(families())
    model, x = prob.model, prob.x0 + 0.01
    v = np.zeros_like(x)
    total = model.forces(x, v)
    parts = sum(model.forces(x, v, role=r) for r in ("internal", "external", "contact"))
    np.testing.assert_allclose(parts, total, atol=1e-12)
    assert abs(model.forces(x, v, role="internal").sum(axis=0)).max() < 1e-10  # pair laws


def test_a_model_refuses_what_is_not_a_family():
    with pytest.raises(ValueError, match="Interaction"):
        ClothModel.grid(3, 3, families=[lambda x: x])
