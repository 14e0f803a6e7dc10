"""Coarse-to-fine continuation: problems resampled in time, controls carried between grids,
and a cloth problem that reaches the direct solve's objective in fewer fine iterations."""
import casadi as ca
import numpy as np
import pytest

from casadi_keyframe import (CenterOfMassKeyframe, ControlProblem, InitialVelocity,
                             ParticleKeyframe, RegionTarget, Smoothness, StateKeyframe,
                             StepForces, load_problem, solve)
from casadi_keyframe.controls import resample_steps
from casadi_keyframe.integrators import LinearizedBackwardEuler, SymplecticEuler
from casadi_keyframe.models import FlockModel, FlockParams, wander_forces
from casadi_keyframe.shapes import square

from helpers import InterruptAfter

FREE = FlockParams(avoid_strength=0.0, match_strength=0.0, center_strength=0.0)


def flock(*, steps=24, dt=0.1, params=FREE, n=5, dim=2, seed=0, controls=None, wander=0.3):
    """A small flock with a keyframe term of every kind, each at a frame divisible by 4, and
    a guess.  With the default ``FREE`` parameters no force acts but the controls and the
    stored wander: a linear model."""
    rng = np.random.default_rng(seed)
    guess = None if controls is not None else 0.1 * rng.standard_normal(steps * n * dim)
    model = FlockModel(rng.uniform(0.5, 2.0, n), dim, params)
    x0 = rng.uniform(0, 3, (n, dim))
    obj = (StateKeyframe(steps // 3, x=rng.uniform(0, 3, (n, dim)))
           + ParticleKeyframe(steps // 2, [1, 3], x=[[5] * dim, [6] * dim])
           + CenterOfMassKeyframe(2 * steps // 3, x=[3] * dim, v=[1] + [0] * (dim - 1))
           + RegionTarget(steps, square((2, 2), 1))
           + Smoothness(0.01, temporal=0.01))
    return ControlProblem(model=model, integrator=SymplecticEuler(), x0=x0, v0=np.zeros((n, dim)),
                          steps=steps, dt=dt, controls=controls or StepForces(), objective=obj,
                          external=wander_forces(steps, n, dim, strength=wander, seed=seed + 1),
                          name="free_flock", guess=guess)


def cost(term, prob, u) -> float:
    return float(term.symbolic(ca.DM(u), prob.controls, prob.dt))


def step_function(values, horizon, t):
    """The piecewise-constant function of time that per-step ``values`` stand for."""
    steps = values.shape[0]
    return values[np.minimum((t / horizon * steps).astype(int), steps - 1)]


# -- the resampled problem --------------------------------------------------------------------
def test_resampled_problem_keeps_keyframe_times_and_scales_steps():
    prob = flock(steps=24, dt=0.1)
    coarse = prob.resampled(0.2)
    assert (coarse.steps, coarse.dt, coarse.horizon) == (12, pytest.approx(0.2), pytest.approx(2.4))
    for fine, c in zip(prob.objective_terms.state_terms, coarse.objective_terms.state_terms):
        assert type(c) is type(fine) and c is not fine
        assert c.frame * coarse.dt == pytest.approx(fine.frame * prob.dt)
    assert [t.frame for t in coarse.objective_terms.state_terms] == [4, 6, 8, 12]
    # the original is untouched: its terms, controls and guess still belong to 24 steps
    assert [t.frame for t in prob.objective_terms.state_terms] == [8, 12, 16, 24]
    assert prob.controls.steps == 24 and prob.initial_controls().size == prob.size
    assert coarse.size == prob.size // 2 and coarse.initial_controls().size == coarse.size
    # stored forces and guess keep their impulse; the model and initial state are shared
    assert coarse.external.sum(0) * coarse.dt == pytest.approx(prob.external.sum(0) * prob.dt)
    assert np.allclose(coarse.initial_controls().sum() * coarse.dt,
                       prob.initial_controls().sum() * prob.dt)
    assert coarse.model is prob.model and np.array_equal(coarse.x0, prob.x0)
    u = coarse.initial_controls()
    assert np.isfinite(coarse.objective(u)) and prob.resampled(0.1) is prob


@pytest.mark.parametrize("dt, match", [
    (0.07, "does not divide the horizon of 2.4 s .* choose dt = horizon / k"),
    (0.3, "StateKeyframe@8 at t = 0.8 s falls between steps .* choose a dt"),  # frame 2.67
    (0.0, "a time step must be a positive number"),
])
def test_a_bad_time_step_is_refused_with_the_fix(dt, match):
    prob = flock(steps=24, dt=0.1)
    with pytest.raises(ValueError, match="free_flock: .*" + match):
        prob.resampled(dt)


@pytest.mark.parametrize("continuation, match", [
    ([0.1, 0.2], "decrease strictly"),
    ([0.05], "decrease strictly"),                  # finer than the problem's own dt
    ([], "empty"),
    ([0.3, 0.2], "falls between steps"),
])
def test_a_bad_continuation_is_refused_before_any_solve(continuation, match):
    prob = flock(steps=24, dt=0.1)
    with pytest.raises(ValueError, match=match):
        solve(prob, continuation=continuation, quiet=True)


def test_per_step_bounds_follow_the_controls():
    controls = StepForces(lower=-np.arange(1, 25).repeat(10).astype(float), upper=1.0)
    prob = flock(steps=24, dt=0.1, controls=controls)
    lb, ub = prob.resampled(0.2).bounds()
    assert lb.size == prob.size // 2 and np.all(ub == 1.0)
    assert np.allclose(lb.reshape(12, -1)[:, 0], -(np.arange(1, 25, 2) + 0.5))


# -- carrying controls between grids ----------------------------------------------------------
def test_resampling_keeps_force_versus_time_and_impulse():
    prob = flock(steps=12, dt=0.2)
    horizon = prob.horizon
    mid = (np.arange(12) + 0.5) * prob.dt
    force = np.sin(2 * np.pi * mid / horizon)[:, None, None] * np.array([1.0, -2.0])
    u = np.broadcast_to(force, prob.controls.block_shape).ravel()
    fine_u = prob.controls.resample(u, 24)
    coarse_f, fine_f = u.reshape(12, 5, 2), fine_u.reshape(24, 5, 2)
    t = np.random.default_rng(1).uniform(0, horizon, 500)
    assert np.array_equal(step_function(fine_f, horizon, t), step_function(coarse_f, horizon, t))
    assert fine_f.sum(0) * prob.dt / 2 == pytest.approx(coarse_f.sum(0) * prob.dt, abs=1e-12)
    # newtons, not impulses: the fine values sample the same smooth force, within O(dt)
    fine_mid = (np.arange(24) + 0.5) * prob.dt / 2
    exact = np.sin(2 * np.pi * fine_mid / horizon)
    assert np.abs(fine_f[:, 0, 0] - exact).max() < 2 * np.pi / horizon * prob.dt / 2
    # onto a grid that does not nest: the same impulse
    odd = resample_steps(coarse_f, 7)
    assert odd.sum(0) * horizon / 7 == pytest.approx(coarse_f.sum(0) * prob.dt, abs=1e-12)


def test_resample_round_trip_and_initial_velocities():
    values = np.random.default_rng(2).standard_normal((6, 3))
    assert np.allclose(resample_steps(resample_steps(values, 18), 6), values)
    controls = InitialVelocity()
    controls.bind(4, 2, 10)
    u = np.arange(8.0)
    assert np.array_equal(controls.resample(u, 20), u)


def test_coarse_optimal_forces_give_the_same_motion_on_the_fine_grid():
    """A model with no forces but the controls: velocities at shared times are equal (the
    impulse is kept); positions differ only by symplectic Euler's O(dt) error, which for a
    force held over two half steps instead of one step is exactly dt0/4 * (v - v0)."""
    fine = flock(steps=24, dt=0.1, wander=0.0)
    coarse = fine.resampled(0.2)
    r = solve(coarse, maxiter=100, quiet=True)
    u = coarse.controls.resample(r.x, fine.steps)
    tc, tf = coarse.simulate(r.x), fine.simulate(u)
    assert np.allclose(tf.v[::2], tc.v, rtol=0, atol=1e-10)
    assert np.allclose(tc.x - tf.x[::2], coarse.dt / 4 * (tc.v - tc.v[0]), rtol=0, atol=1e-10)
    gap = np.linalg.norm(tf.x[::2] - tc.x, axis=-1).max()
    assert gap < 0.1 * np.linalg.norm(tc.x - tc.x[0], axis=-1).max()
    # Smoothness is a time integral: the force cost is the same at both steps; the staircase
    # keeps its jumps over half the step, so their (rate of change) cost doubles
    force, rate = Smoothness(0.01), Smoothness(0.0, temporal=0.01)
    assert cost(force, fine, u) == pytest.approx(cost(force, coarse, r.x), rel=1e-9)
    assert cost(rate, fine, u) == pytest.approx(2 * cost(rate, coarse, r.x), rel=1e-9)
    # and the fine problem's keyframe error is nearly the coarse optimum's
    miss_fine = fine.breakdown(u)["keyframe_error"]
    miss_coarse = coarse.breakdown(r.x)["keyframe_error"]
    assert miss_fine == pytest.approx(miss_coarse, rel=0.1)
    assert miss_fine < 0.5 * fine.breakdown(fine.controls.zeros())["keyframe_error"]


# -- solve(continuation=...) ------------------------------------------------------------------
def test_continuation_records_each_stage():
    prob = flock(steps=24, dt=0.1, params=FlockParams())
    r = solve(prob, maxiter=15, quiet=True, continuation=[0.4, 0.2])
    assert [s["dt"] for s in r.stages] == pytest.approx([0.4, 0.2, 0.1])
    assert [s["steps"] for s in r.stages] == [6, 12, 24]
    assert r.nit == sum(s["nit"] for s in r.stages) == len(r.history)
    assert all(s["nit"] <= 15 for s in r.stages)  # maxiter is per stage
    assert [h["stage"] for h in r.history] == sorted(h["stage"] for h in r.history)
    assert {h["dt"] for h in r.history if h["stage"] == 2} == {0.1}
    assert len(r.timings["stage_seconds"]) == 3 and r.nfev == sum(s["nfev"] for s in r.stages)
    assert r.x.size == prob.size and r.trajectory.steps == 24
    assert r.fun == pytest.approx(prob.objective(r.x), rel=1e-12)
    assert r.summary()["stages"][0]["fun"] == r.stages[0]["fun"]


def test_interrupt_in_an_early_stage_keeps_its_best_on_the_final_grid(tmp_path):
    prob = flock(steps=24, dt=0.1, params=FlockParams())
    ckpt = tmp_path / "best.npz"
    r = solve(prob, gradient=InterruptAfter(8), maxiter=100, quiet=True, checkpoint=ckpt,
              continuation=[0.2])
    assert "stage 0" in r.message and "interrupted" in r.message and not r.success
    assert len(r.stages) == 2 and r.x.size == prob.size
    assert r.stages[1]["skipped"] == "signal" and r.stages[1]["nit"] == 0  # said, not run
    assert r.fun == pytest.approx(prob.objective(r.x), rel=1e-12)
    assert r.fun < prob.objective(prob.initial_controls())
    saved = np.load(ckpt)  # the stage's best, carried to the final grid and judged there
    assert saved["u"].size == prob.size and int(saved["stage"]) == 0
    np.testing.assert_array_equal(saved["u"], r.x)
    assert float(saved["stage_dt"]) == pytest.approx(0.1)
    assert float(saved["fun"]) == pytest.approx(r.fun, rel=1e-12)


# -- the claim: fewer fine iterations on a cloth ----------------------------------------------
def test_cloth_continuation_reaches_the_direct_objective_in_fewer_fine_iterations():
    """5 x 5 cloth_shapes, 48 steps of 1/60 s, keyframes at frames 16, 32, 48; stages 1/15,
    1/30, 1/60 s; the exact adjoint (the swapped one stalls the direct solve after a few
    iterations, see the module docstring of problems/cloth_shapes.py)."""
    prob = load_problem("cloth_shapes", rows=5, cols=5, steps=48, strain_weight=0)
    # Measured with modified PCG and without the strain limit; the searches' paths depend on
    # roundoff and on the objective, and with CHOLMOD (the default solver since) the
    # continuation ends in another local minimum (objective 0.079 against the direct solve's
    # 0.068 at 40 iterations), with the strain limit on (the default since) at 0.0218 against
    # 0.0161: the claim is for this path, not a rule (see notebooks/optimizer_convergence).
    prob.integrator = LinearizedBackwardEuler("cg")
    maxiter = 40
    direct = solve(prob, maxiter=maxiter, quiet=True, stop="method")
    cont = solve(prob, maxiter=maxiter, quiet=True, continuation=[1 / 15, 1 / 30], stop="method")
    assert [s["steps"] for s in cont.stages] == [12, 24, 48]
    assert cont.fun <= direct.fun * (1 + 1e-3)
    fine = [h["objective"] for h in cont.history if h["stage"] == 2]
    reached = next(i for i, f in enumerate(fine, 1) if f <= direct.fun * (1 + 1e-3))
    assert reached < direct.nit, (reached, direct.nit)


# -- the command line -------------------------------------------------------------------------
def test_cli_solves_with_continuation(tmp_path, capsys):
    import json

    from casadi_keyframe.cli import main
    from casadi_keyframe.cli.values import parse_time_steps

    assert parse_time_steps("1/15, 1/30,0.0125") == pytest.approx([1 / 15, 1 / 30, 0.0125])
    with pytest.raises(ValueError, match="--continuation expects"):
        parse_time_steps("1/15,fast")
    base = ["solve", "flock_race", "--set", "agents=6", "--set", "steps=40", "--set",
            "keyframes=4", "--maxiter", "5", "--quiet", "--no-animation"]
    assert main(base + ["--out", str(tmp_path), "--continuation", "1/10,1/20"]) == 3  # maxiter
    out = capsys.readouterr().out
    assert "stage 0: dt 0.1 s, 20 steps" in out and "stage 1: dt 0.05 s, 40 steps" in out
    assert out.count("iteration limit reached (5 iterations in this stage)") >= 2  # the stages' messages are printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [s["steps"] for s in summary["stages"]] == [20, 40]
    assert main(base + ["--out", str(tmp_path), "--continuation", "0.4"]) == 2
    assert "falls between steps" in capsys.readouterr().err
