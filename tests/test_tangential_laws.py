"""A tangential law is one class the hold calls (models/contact/tangential.py): a law written
here, anisotropic friction, slides and stops as its coefficients say, its kernels are its
impulse's derivatives and the routes agree through it, with no other file touched; Coulomb's
law given as an object is the number's."""
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pytest

from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import (ClothModel, ClothParams, Contact, Coulomb, Plane,
                                    TangentialLaw)
from casadi_keyframe.models.contact.tangential import tangential_kernels
from casadi_keyframe.simulate import simulate

from helpers import assert_exact_routes

G = 9.81


@dataclass(frozen=True)
class Anisotropic(TangentialLaw):
    """Coulomb friction with coefficient ``mu`` along ``axis`` (a unit direction in the
    body's tangent plane) and ``across`` it, by maximal dissipation over an ellipse: ``F =
    -N (mu^2 s_a + across^2 s_c) / sqrt(mu^2 |s_a|^2 + across^2 |s_c|^2)``, the slip split
    along and across the axis (minus the slip gradient of the convex ``N sqrt(mu^2 |s_a|^2 +
    across^2 |s_c|^2)``); a sticking contact slides when its tangential impulse leaves the
    ellipse ``(r_a / mu)^2 + (r_c / across)^2 <= N^2``."""

    mu: float
    across: float
    axis: tuple = (1.0, 0.0, 0.0)

    name = "anisotropic"
    COEFFICIENTS = {"mu": 1, "across": 1, "axis": 3}

    @staticmethod
    def impulse(N, slip, normal, mu, across, axis):
        along = axis * ca.dot(axis, slip)
        weighted = mu ** 2 * along + across ** 2 * (slip - along)
        return -N * weighted / ca.sqrt(ca.dot(weighted, slip) + 1e-30)

    def leaves(self, tangential, N):
        axis = np.asarray(self.axis, float)
        along = tangential @ axis
        across = np.linalg.norm(tangential - along[:, None] * axis, axis=1)
        return np.hypot(along / self.mu, across / self.across) > N * (1 + 1e-9) + 1e-15


def thrown_sheet(friction, speed=3.0, steps=80):
    """How far a 6 x 6 sheet resting on the held ground, thrown along x, slides."""
    ground = Plane((0, 0, 0), contact=Contact(friction=friction))
    model = ClothModel.grid(6, 6, width=0.5, height=0.5, plane="xy", mass=0.3,
                            colliders=[ground], collision="constraint",
                            params=ClothParams(air_drag=0.0))
    x0 = model.rest_positions - model.rest_positions.mean(0) + [0, 0, ground.contact.thickness]
    v0 = np.zeros_like(x0)
    v0[:, 0] = speed
    traj = simulate(LinearizedBackwardEuler(), model, x0, v0, np.zeros((steps, model.n, 3)),
                    1 / 60)
    return traj, traj.x[-1, :, 0].mean() - x0[:, 0].mean()


def test_coulomb_given_as_a_law_is_the_number():
    by_number, _ = thrown_sheet(0.3, steps=20)
    by_law, _ = thrown_sheet(Coulomb(0.3), steps=20)
    np.testing.assert_array_equal(by_number.x, by_law.x)


def test_a_law_with_equal_coefficients_is_coulombs():
    coulomb, _ = thrown_sheet(0.4, steps=20)
    same, _ = thrown_sheet(Anisotropic(0.4, 0.4), steps=20)
    np.testing.assert_allclose(same.x, coulomb.x, rtol=0, atol=1e-12)


@pytest.mark.parametrize("axis, mu", [((1.0, 0.0, 0.0), 0.3), ((0.0, 1.0, 0.0), 0.9)])
def test_an_anisotropic_sheet_stops_after_v2_over_2_mu_g_along_its_slide(axis, mu):
    """Thrown along x, the sheet brakes with the coefficient along x: ``mu`` when the axis
    is x, ``across`` when it is y."""
    law = Anisotropic(0.3, 0.9, axis)
    traj, travelled = thrown_sheet(law)
    assert np.abs(traj.v[-1]).max() < 1e-6  # stopped and stuck
    assert abs(traj.x[-1, :, 1].mean() - traj.x[0, :, 1].mean()) < 1e-9  # no sideways drift
    assert travelled == pytest.approx(3.0 ** 2 / (2 * mu * G), rel=0.1)


def test_gradients_through_an_anisotropic_slide_are_the_symbolic_steps():
    """The hand adjoint and the tangent pass through the new law's kernels agree with CasADi
    reverse mode through the symbolic step (how the whole step's gradient meets the forward
    pass with friction is issue 41's)."""
    ground = Plane((0, 0, 0), (0, -0.2, 1), contact=Contact(friction=Anisotropic(
        0.3, 0.7, (1.0, 0.0, 0.0))))
    model = ClothModel.grid(4, 4, width=0.6, height=0.6, plane="xy", mass=0.3,
                            colliders=[ground], collision="guarded")
    x0 = model.rest_positions + [0, 0, 0.012]
    v0 = np.zeros_like(x0)
    v0[:, 0], v0[:5, 1], v0[:, 2] = 1.0, 0.4, -0.3
    steps = 4
    prob = ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                          v0=v0, steps=steps, dt=1 / 60, controls=StepForces(),
                          objective=StateKeyframe(steps, x=x0 + [0.1, 0.05, 0.0])
                          + Smoothness(1e-4))
    u = 0.002 * np.random.default_rng(0).standard_normal(prob.size)
    held = [r.held for r in prob.simulate(u).records if r.held is not None]
    assert any((~h.stick).any() for h in held) and any(h.stick.any() for h in held)
    assert_exact_routes(prob, u)


def test_the_seams_kernels_are_the_derivatives_of_the_laws_impulse():
    """The kernels a law gets (impulse, vjp, jvp) against central differences of its own
    linearized impulse ``F - B q``, stable over three decades of h, for a sliding particle
    over a turning plane; ``B`` is the slip derivative of F, projected on the tangent plane,
    symmetric and positive semi-definite."""
    law = Anisotropic(0.3, 0.7, (0.6, 0.8, 0.0))
    kernels = tangential_kernels(Anisotropic, Plane, 0.5)
    rng = np.random.default_rng(3)
    plane = Plane((0, 0, 0), contact=Contact(friction=law),
                  motion=lambda t: (np.array([[np.cos(t), -np.sin(t), 0],
                                              [np.sin(t), np.cos(t), 0], [0, 0, 1.0]]),
                                    np.zeros(3)))
    geometry = [*plane.geometry(0.1), *plane.geometry(0.1 + 1 / 60)]
    x, v = np.array([0.2, 0.1, 0.004]), np.array([0.8, -0.3, -0.2])
    rest = [*geometry, 0.01, 1 / 60, 1.0, 0.02, [0, 0, -G], *law.coefficients()]
    q = 0.1 * rng.standard_normal(3)

    def pushed(x, v):
        F, B, _ = (np.array(a) for a in kernels["impulse"](x, v, *rest))
        return F.ravel() - B.reshape(3, 3) @ q

    dx, dv, lam = rng.standard_normal(3), rng.standard_normal(3), rng.standard_normal(3)
    jvp = np.array(kernels["jvp"](x, v, *rest, q, dx, dv)).ravel()
    central = [(pushed(x + e * dx, v + e * dv) - pushed(x - e * dx, v - e * dv)) / (2 * e)
               for e in (1e-4, 1e-5, 1e-6)]
    for quotient in central:
        np.testing.assert_allclose(quotient, jvp, rtol=1e-6, atol=1e-9 * np.abs(jvp).max())
    gx, gv = (np.array(a).ravel() for a in kernels["vjp"](x, v, *rest, lam, q))
    assert gx @ dx + gv @ dv == pytest.approx(lam @ jvp, rel=1e-12)
    F, B, _ = (np.array(a) for a in kernels["impulse"](x, v, *rest))
    B = B.reshape(3, 3)
    np.testing.assert_allclose(B, B.T, atol=1e-15)
    assert np.linalg.eigvalsh(B).min() > -1e-12
    e = 1e-6  # B is minus F's slip derivative on the tangent plane (z: the plane turns about
    J = np.zeros((3, 3))  # it), symmetrized; N does not change along the plane
    for k in range(2):
        step = np.eye(3)[k]
        J[:, k] = (np.array(kernels["impulse"](x, v + e * step, *rest)[0])
                   - np.array(kernels["impulse"](x, v - e * step, *rest)[0])).ravel() / (2 * e)
    np.testing.assert_allclose(-B, (J + J.T) / 2, rtol=1e-6, atol=1e-9 * np.abs(B).max())
