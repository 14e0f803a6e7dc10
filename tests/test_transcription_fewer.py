"""The transcription where the controls are fewer than a force per free particle (initial
velocities, forces on some particles): the steps' defects vanish on a simulation of given
controls, their Jacobian (the controls' columns included) and their multiplier-weighted
curvature are their central differences, a small problem is solved end to end with its
controls replaying the positions, and what still cannot be written is refused by name."""
import numpy as np
import pytest

import casadi_keyframe as ck
from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe
from casadi_keyframe.controls import InitialVelocity, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler, SymplecticEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.optimize.positions import TranscriptionError
from casadi_keyframe.optimize.positions.defects import StepDefects

STEPS = 12
KINDS = {"velocity": InitialVelocity, "some forces": lambda: StepForces(agents=[5, 6, 7, 12])}


def reachable(controls, seed=0):
    """``(problem, u)``: a 4 x 4 sheet pinned at two corners whose keyframe (its last frame,
    within 1 cm) is the run of the random controls ``u``."""
    model = ClothModel.grid(4, 4, pinned=[0, 3])
    x0 = model.rest_positions
    common = dict(model=model, integrator=LinearizedBackwardEuler("direct"), x0=x0,
                  v0=np.zeros_like(x0), steps=STEPS, dt=1 / 30, controls=controls, name="sheet")
    base = ControlProblem(objective=StateKeyframe(STEPS, x=x0), **common)
    u = np.random.default_rng(seed).standard_normal(base.size)
    u *= 0.3 if isinstance(controls, InitialVelocity) else 0.003
    target = base.simulate(u, records=False).x[STEPS]
    return ControlProblem(objective=StateKeyframe(STEPS, x=target, position_weight=100.0,
                                                  tolerance=0.01) + Smoothness(1e-4),
                          **common), u


def _point(d, u, rng):
    """A point off the dynamics with every spring taut (the forces smooth there)."""
    x = d.problem.simulate(u, records=False).x
    x[1:] = 1.15 * x[1:] + 0.001 * rng.standard_normal(x[1:].shape)
    return np.concatenate([d.unknowns(x), u + 0.01 * rng.standard_normal(u.size)])


@pytest.mark.parametrize("kind", KINDS)
def test_the_defects_vanish_on_a_simulation_of_given_controls(kind):
    prob, u = reachable(KINDS[kind]())
    d = StepDefects(prob)
    w = np.concatenate([d.unknowns(prob.simulate(u, records=False).x), u])
    assert np.abs(d.values(w)).max() <= 1e-12
    w[d.size:] *= 1.1  # other controls, the same positions: no longer their motion
    assert np.abs(d.values(w)).max() > 1e-6


@pytest.mark.parametrize("kind", KINDS)
def test_the_defects_jacobian_and_curvature_are_their_central_differences(kind):
    prob, u = reachable(KINDS[kind]())
    d = StepDefects(prob)
    rng = np.random.default_rng(1)
    w = _point(d, u, rng)
    J = d.jacobian(w)
    lam = rng.standard_normal(d.rows)
    H = d.curvature(w, lam)
    for part in (slice(0, d.size), slice(d.size, d.width)):  # positions, then controls
        dw = np.zeros(d.width)
        dw[part] = rng.standard_normal(dw[part].size)
        slope, turn = J @ dw, H @ dw
        assert np.linalg.norm(slope) > 0  # (the first step is linear in v_0: u bends nothing)
        for h in (1e-5, 1e-6, 1e-7):  # stable over three decades: smooth here
            quotient = (d.values(w + h * dw) - d.values(w - h * dw)) / (2 * h)
            assert np.linalg.norm(quotient - slope) <= 1e-6 * np.linalg.norm(slope)
            bend = (d.jacobian(w + h * dw).T @ lam - d.jacobian(w - h * dw).T @ lam) / (2 * h)
            assert np.linalg.norm(bend - turn) <= 1e-5 * np.linalg.norm(turn) + 1e-6


def test_the_patterns_hold_every_entry():
    prob, u = reachable(InitialVelocity())
    d = StepDefects(prob)
    w = _point(d, u, np.random.default_rng(2))
    pattern = d.jacobian_pattern()
    J = d.jacobian(w)
    assert (abs(J) + pattern).nnz == pattern.nnz
    H = d.curvature(w, np.ones(d.rows))
    assert (abs(H) + d.curvature_pattern()).nnz == d.curvature_pattern().nnz


@pytest.mark.parametrize("kind", KINDS)
def test_a_reachable_keyframe_is_met_and_the_controls_replay_the_positions(kind):
    prob, u = reachable(KINDS[kind]())
    result = ck.solve(prob, method="transcription", maxiter=60, quiet=True)
    assert result.status == 0, result.message
    assert result.breakdown["misses"][0]["rms_position_error"] <= 0.01
    assert prob.control_cost(result.x)[0] <= prob.control_cost(u)[0]
    gap = float(result.message.split("their run is within ")[1].split(" mm")[0])
    assert gap <= 0.1


def test_what_still_cannot_be_written_is_refused_by_name():
    prob, _ = reachable(InitialVelocity())
    explicit, _ = reachable(InitialVelocity())
    explicit.integrator = SymplecticEuler()  # a step the transcription does not invert
    with pytest.raises(TranscriptionError, match="linearized backward Euler.*lbfgsb"):
        StepDefects(explicit)
    with pytest.raises(TranscriptionError, match="hessian=exact"):
        ck.solve(prob, method="transcription", options={"hessian": "exact"}, quiet=True)
    full, _ = reachable(StepForces())
    with pytest.raises(TranscriptionError, match="closed form"):
        StepDefects(full)
