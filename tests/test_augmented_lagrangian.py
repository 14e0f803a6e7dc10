"""Hard keyframes: the augmented Lagrangian drives the miss a penalty leaves towards zero."""
import numpy as np
import pytest

from casadi_keyframe import CenterOfMassKeyframe, ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.optimize import solve_augmented
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.objectives import PhysicalLimits
from casadi_keyframe.optimize import solve
from casadi_keyframe.scenes.sheets import hanging_sheet
from casadi_keyframe.simulate import simulate

OPTIONS = {"maxiter": 60, "quiet": True, "stop": "method"}  # every round, to compare


def settled(model, seconds=5.0, dt=1 / 30):
    """Positions of the passive sheet after ``seconds`` of hanging from its pins."""
    x0 = model.rest_positions
    steps = int(round(seconds / dt))
    traj = simulate(LinearizedBackwardEuler("direct"), model, x0, np.zeros_like(x0),
                    np.zeros((steps,) + x0.shape), dt, records=False)
    return traj.x[-1]


def swing(weight=20.0, alpha=2e-2):
    """A soft 3 x 3 sheet, its free particles swung 20 cm forward in 1/3 s: its forces cost
    enough (``alpha``) that the keyframe penalty alone leaves a miss of millimetres.

    It starts hanging at rest under its weight, springs stretched: from the unstretched rest
    shape the penalty's optimum keeps a spring at exactly its rest length after the first
    step, on the Choi-Ko law's kink, and the later rounds' line searches fail there."""
    model = hanging_sheet(3, stretch=50.0, ground=False)
    x0 = settled(model)
    free = np.setdiff1d(np.arange(model.n), model.pinned)
    steps = 10
    objective = (StateKeyframe(steps, x=x0[free] + [0.0, 0.2, 0.0], position_weight=weight,
                               agents=free)
                 + Smoothness(alpha))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"),
                          x0=x0, v0=np.zeros_like(x0), steps=steps, dt=1 / 30,
                          controls=StepForces(), objective=objective, name="swing",
                          limits=PhysicalLimits(stretch=1.5))  # it hangs at 1.28 by its weight


def rms_miss(result):
    return result.breakdown["misses"][0]["rms_position_error"]


@pytest.fixture(scope="module")
def penalty():
    return solve(swing(), **OPTIONS)


def test_multipliers_shrink_the_penalty_miss(penalty):
    prob = swing()
    result = solve_augmented(prob, rounds=4, **OPTIONS)
    misses = [s["misses"][0]["rms_position_error"] for s in result.stages]
    assert len(result.stages) == 4 and result.nit == sum(s["nit"] for s in result.stages)
    assert misses[0] == pytest.approx(rms_miss(penalty), rel=1e-6)  # round 0 is the penalty
    assert rms_miss(penalty) > 0.002  # the control cost pulls (3.6 mm, measured)
    assert misses[-1] < rms_miss(penalty) / 5  # 0.27 mm, measured
    assert all(b < a for a, b in zip(misses, misses[1:]))
    # the result is scored on the true problem, not the shifted one of the last round
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)
    assert result.breakdown["control_cost"] > penalty.breakdown["control_cost"]


def test_a_weight_schedule_shrinks_it_and_multipliers_on_top_shrink_it_further(penalty):
    schedule = solve_augmented(swing(), rounds=3, weight_growth=10.0, multipliers=False,
                               **OPTIONS)
    both = solve_augmented(swing(), rounds=3, weight_growth=10.0, **OPTIONS)
    assert [s["weight_scale"] for s in schedule.stages] == [1.0, 10.0, 100.0]
    assert rms_miss(schedule) < rms_miss(penalty) / 20  # 0.055 mm, measured
    assert rms_miss(both) < rms_miss(schedule) / 2  # 0.0023 mm, measured


def test_each_keyframe_gets_its_own_multiplier():
    """Two keyframes, each with its own shift (keyed by its place in the objective): both
    misses shrink round by round, and the result is scored on the true targets."""
    prob = swing()
    first = prob.objective_terms.state_terms[0]
    halfway = StateKeyframe(5, x=prob.x0[first.particles] + [0.0, 0.05, 0.0],
                            position_weight=20.0, agents=first.particles)
    prob = prob.with_objective(halfway + first.at_frame(first.frame) + Smoothness(2e-2))
    result = solve_augmented(prob, rounds=3, **OPTIONS)
    misses = np.array([[m["rms_position_error"] for m in s["misses"]] for s in result.stages])
    assert misses.shape == (3, 2)
    assert (misses[-1] < misses[0] / 3).all()
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)


def test_an_aiming_keyframe_aims_past_its_target_and_is_judged_by_it():
    prob = swing()
    term = prob.objective_terms.state_terms[0]
    aiming = term.aiming(dx=0.1, dv=-1.0, weight_scale=3.0)
    again = prob.with_objective(aiming + Smoothness(2e-2))
    bound = again.objective_terms.state_terms[0]
    np.testing.assert_array_equal(bound.position_target, term.position_target)  # goal stays
    assert bound.velocity_target is None and term.velocity_target is None
    np.testing.assert_array_equal(bound.particles, term.particles)
    assert bound.position_weight == 3 * term.position_weight
    traj = prob.simulate()
    x = traj.x[term.frame][term.particles]
    aim = term.position_target + 0.1
    assert bound.value(traj) == pytest.approx(0.5 * bound.position_weight * np.sum((x - aim) ** 2))
    assert bound.miss(traj) == term.miss(traj)
    assert bound.shortfall(traj) == term.shortfall(traj) is not None


def test_the_rounds_stop_once_the_goal_is_met_and_a_resumed_run_keeps_its_multipliers(tmp_path):
    from casadi_keyframe.saved import Checkpoint, read_run

    prob = swing()
    tight = StateKeyframe(10, x=prob.objective_terms.state_terms[0].position_target,
                          agents=prob.objective_terms.state_terms[0].particles,
                          position_weight=20.0, tolerance=1e-3)
    prob = prob.with_objective(tight + Smoothness(2e-2))
    ckpt = Checkpoint(tmp_path / "checkpoint.npz", problem="swing")
    result = solve_augmented(prob, rounds=6, maxiter=60, quiet=True, checkpoint=ckpt)
    assert result.success and 1 < len(result.stages) < 6  # stopped when within 1 mm
    assert rms_miss(result) <= 1e-3 < result.stages[0]["misses"][0]["rms_position_error"]
    meta = read_run(tmp_path)["meta"]
    assert meta["rounds_round"] == len(result.stages) - 1
    again = solve_augmented(prob, rounds=6, maxiter=60, quiet=True, resume=meta,
                            u0=read_run(tmp_path)["u"])
    assert again.stages[0]["stage"] == meta["rounds_round"]  # the round it stopped in
    assert again.stages[0]["weight_scale"] == 1.0 and again.success
    assert rms_miss(again) <= 1e-3  # its multipliers kept: a fresh round 0 would miss


@pytest.mark.parametrize("kwargs, message", [
    ({"rounds": 0}, "rounds must be"),
    ({"weight_growth": 0.5}, "weight_growth must be"),
])
def test_bad_options_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        solve_augmented(swing(), **kwargs)


def test_a_problem_without_state_keyframe_is_refused():
    prob = swing()
    com = prob.with_objective(CenterOfMassKeyframe(10, x=[0, 0.2, 0]) + Smoothness(1e-2))
    with pytest.raises(ValueError, match="no StateKeyframe"):
        solve_augmented(com)


def test_the_rounds_stop_at_an_interrupt_or_the_time_limit_and_say_so():
    from helpers import InterruptAfter

    from casadi_keyframe.optimize import INTERRUPTED, LIMIT

    stopped = solve_augmented(swing(), rounds=3, gradient=InterruptAfter(30), **OPTIONS)
    assert stopped.status == INTERRUPTED and not stopped.success
    assert len(stopped.stages) < 3 and stopped.stages[-1]["status"] == INTERRUPTED
    timed = solve_augmented(swing(), rounds=50, time_limit=0.3, **OPTIONS)
    assert timed.status == LIMIT and "time limit reached (0.3 s)" in timed.message
    assert len(timed.stages) < 50


def test_the_lancelot_rule_moves_a_multiplier_only_where_its_miss_shrank():
    """always=False (multiple shooting's defects and held keyframes): where the miss fell to
    a quarter of its last size the multiplier moves by w c and the weight stays; elsewhere
    the weight grows and the multiplier stays; the first update moves every multiplier."""
    from casadi_keyframe.optimize.multipliers import Multipliers

    mult = Multipliers({"a": 2.0, "b": 2.0}, growth=10.0, always=False)
    mult.update({"a": np.array([1.0]), "b": np.array([1.0])})
    assert mult.lam["a"] == mult.lam["b"] == pytest.approx(2.0)
    assert mult.weights == {"a": 2.0, "b": 2.0}
    mult.update({"a": np.array([0.2]), "b": np.array([0.5])})  # a shrank to 1/5, b to 1/2
    assert mult.lam["a"] == pytest.approx(2.4) and mult.weights["a"] == 2.0
    assert mult.lam["b"] == pytest.approx(2.0) and mult.weights["b"] == 20.0
    schedule = Multipliers({"a": 2.0}, growth=10.0)  # always: the keyframe rounds' schedule
    schedule.update({"a": np.array([1.0])})
    schedule.update({"a": np.array([0.9])})
    assert schedule.lam["a"] == pytest.approx(2.0 + 20.0 * 0.9) and schedule.weights["a"] == 200
