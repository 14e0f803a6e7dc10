"""The keyframes held as a constraint on a window of late steps: the window's Jacobian
products (exact against central differences and each other), the landing step, and
``solve(..., finish=...)``: a search that stops short lands, the story stays one."""
import json

import numpy as np
import pytest
from test_augmented_lagrangian import swing

from casadi_keyframe import InitialVelocity, Smoothness, StateKeyframe, load_problem
from casadi_keyframe.optimize import CONVERGED, SolveSettings, solve
from casadi_keyframe.optimize.finish import (Finish, KeyframeConstraint, check_finish,
                                             finish_options, land, lower_effort)
from casadi_keyframe.simulate import tangent


def tight(prob, tolerance=1e-3, strain=None):
    """``prob`` (the swing) with its keyframe's tolerance ``tolerance`` (and a ``strain``
    term): its penalty search stops millimetres off."""
    t = prob.objective_terms.state_terms[0]
    objective = (StateKeyframe(t.frame, x=t.x, position_weight=20.0, agents=t.agents,
                               tolerance=tolerance) + Smoothness(2e-2))
    return prob.with_objective(objective if strain is None else objective + strain)


@pytest.mark.parametrize("first", [0, 4])
def test_the_window_products_are_exact_and_transposes(first):
    prob = swing()
    constraint = KeyframeConstraint(prob, first)
    rng = np.random.default_rng(first)
    u = 0.05 * rng.standard_normal(prob.size)
    traj = prob.simulate(u)
    block = prob.size // prob.steps
    d = rng.standard_normal(prob.size)
    d[:first * block] = 0.0
    w = rng.standard_normal(constraint.size)
    lin = constraint.linearize(traj)
    Jd, JTw = lin.jvp(d), lin.vjp(w)
    assert w @ Jd == pytest.approx(d @ JTw, rel=1e-10)
    h = 1e-6
    fd = (constraint.residual(prob.simulate(u + h * d, records=False))
          - constraint.residual(prob.simulate(u - h * d, records=False))) / (2 * h)
    np.testing.assert_allclose(Jd, fd, rtol=1e-5, atol=1e-8 * np.abs(fd).max())


def test_a_tangent_from_a_later_frame_is_the_whole_tangent_of_a_late_change():
    prob = swing()
    traj = prob.simulate(0.05 * np.random.default_rng(0).standard_normal(prob.size))
    forces = np.random.default_rng(1).standard_normal(prob.external.shape)
    forces[:4] = 0.0
    zero = np.zeros_like(prob.x0)
    whole = tangent(prob.integrator, prob.model, traj, zero, zero, forces)
    late = tangent(prob.integrator, prob.model, traj, zero, zero, forces, start=4)
    for a, b in zip(whole, late):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="start must be a frame"):
        tangent(prob.integrator, prob.model, traj, zero, zero, forces, start=prob.steps + 1)


def test_land_puts_a_missed_keyframe_within_its_tolerance():
    prob = tight(swing())
    short = solve(prob, maxiter=50, quiet=True)
    assert short.status != CONVERGED  # the penalty search stops millimetres off
    result = land(prob, u0=short.x)
    assert result.status == CONVERGED and result.nit >= 1, result.message
    assert result.breakdown["misses"][0]["rms_position_error"] <= 1e-3
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)


def test_solve_finishes_by_landing_and_tells_one_story():
    prob = tight(swing())
    result = solve(prob, maxiter=50, quiet=True, finish="land")
    assert result.status == CONVERGED, result.message
    assert "finish (land)" in result.message
    assert [s["stage"] for s in result.stages] == [0, 1]
    assert result.nit == sum(s["nit"] for s in result.stages)
    assert result.history[-1]["objective"] == pytest.approx(result.fun, rel=1e-9)
    assert result.stages[-1]["fun"] == pytest.approx(result.fun, rel=1e-9)
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)


def test_lower_effort_keeping_the_objective_never_raises_it():
    prob = tight(swing(), tolerance=5e-3)
    start = solve(prob, maxiter=50, quiet=True, finish="land").x
    result = lower_effort(prob, u0=start, maxiter=3, keep_objective=True)
    assert result.fun <= prob.objective(start) + 1e-15
    assert prob.control_cost(result.x)[0] <= prob.control_cost(start)[0]


def test_a_strain_penalty_is_weighed_not_held():
    """A penalty without a tolerance is not refused: the landing holds the keyframe, the
    objective (strain included) judges the finish."""
    from casadi_keyframe.objectives import StrainLimit

    prob = tight(swing(), strain=StrainLimit(limit=1.4))
    result = solve(prob, maxiter=50, quiet=True, finish="land")
    assert result.status == CONVERGED and "finish (land)" in result.message, result.message


def test_the_finish_refuses_what_it_cannot_hold_before_searching():
    with pytest.raises(ValueError, match="StateKeyframe goals only"):
        solve(load_problem("flock_path", agents=6, steps=20), finish="land", maxiter=1)
    with pytest.raises(ValueError, match="per-step forces"):
        solve(swing().with_controls(InitialVelocity()), finish="effort", maxiter=1)
    with pytest.raises(ValueError, match=r"goals only; the objective also has \['MeshKeyframe"):
        solve(load_problem("mesh_keyframes", guess="none", align=True), finish="land",
              maxiter=1)  # its miss is after the best rigid motion: not a position to hold
    check_finish(load_problem("mesh_keyframes", guess="none"), Finish())  # not aligned: held


@pytest.mark.parametrize("finish, message", [
    ("polish", "kind must be one of"), ({"kind": "land", "steps": 3}, "unknown option"),
    ("effort,window", "expected KIND,window=N"), ("land,maxiter=0", "maxiter must be"),
    ({"window": 0}, "window must be"), (3, "finish must be one of"),
])
def test_bad_finish_options_are_refused_by_name(finish, message):
    with pytest.raises(ValueError, match=message):
        SolveSettings(finish=finish)  # the request reads the text form, the finish checks it
    if not isinstance(finish, str):
        with pytest.raises(ValueError, match=message):
            finish_options(finish)


SWING_FILE = '''"""The swing of tests/test_augmented_lagrangian.py, its keyframe held to 1 mm."""
import numpy as np
from casadi_keyframe import ControlProblem, Smoothness, StateKeyframe, StepForces
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.objectives import PhysicalLimits
from casadi_keyframe.scenes.sheets import hanging_sheet
from casadi_keyframe.simulate import simulate

SOLVE = {"maxiter": 50, "finish": "land"}


def build(tolerance: float = 1e-3):
    model = hanging_sheet(3, stretch=50.0, ground=False)
    x = model.rest_positions
    hang = simulate(LinearizedBackwardEuler("direct"), model, x, np.zeros_like(x),
                    np.zeros((150,) + x.shape), 1 / 30, records=False).x[-1]
    free = np.setdiff1d(np.arange(model.n), model.pinned)
    objective = (StateKeyframe(10, x=hang[free] + [0.0, 0.2, 0.0], position_weight=20.0,
                               agents=free, tolerance=tolerance) + Smoothness(2e-2))
    return ControlProblem(model=model, integrator=LinearizedBackwardEuler("direct"), x0=hang,
                          v0=np.zeros_like(hang), steps=10, dt=1 / 30, controls=StepForces(),
                          objective=objective, name="swing", limits=PhysicalLimits(stretch=1.5))
'''


@pytest.mark.parametrize("finish, code", [(None, 0), ("none", 3)])
def test_the_command_line_takes_the_files_finish_or_drops_it(finish, code, tmp_path):
    """The file's SOLVE asks for the landing finish: its run converges in two stages, one
    story; ``--finish none`` runs the search alone, which stops short (exit 3)."""
    from casadi_keyframe.cli import main

    path, out = tmp_path / "swing.py", tmp_path / "out"
    path.write_text(SWING_FILE)
    extra = [] if finish is None else ["--finish", finish]
    assert main(["solve", str(path), "--quiet", "--no-animation", "--no-viewer", "--out",
                 str(out), *extra]) == code
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["stages"]) == (2 if finish is None else 1)
    if finish is None:
        assert "finish (land)" in summary["message"]
        assert summary["stages"][-1]["nit"] >= 1
    assert summary["fun"] == pytest.approx(summary["stages"][-1]["fun"], rel=1e-9)


def test_finish_and_rounds_are_refused_together(capsys):
    from casadi_keyframe.cli import main

    assert main(["solve", "flock_path", "--rounds", "2", "--finish", "land"]) != 0
    assert "the finish holds the keyframes after one search" in capsys.readouterr().err
    with pytest.raises(ValueError, match="choose one"):  # the request itself, from Python too
        SolveSettings(rounds=2, finish="land")


def test_a_time_limit_while_lowering_the_effort_keeps_the_goal_met(monkeypatch):
    """The effort finish starts from a landing: stopped by the clock it has still converged."""
    import casadi_keyframe.optimize.finish.stage as finish
    from casadi_keyframe.optimize.deadline import Deadline

    real = finish.lower_effort
    monkeypatch.setattr(finish, "lower_effort",
                        lambda *a, **k: real(*a, **{**k, "deadline": Deadline.start(1e-9)}))
    prob = tight(swing(), tolerance=5e-3)
    result = solve(prob, maxiter=50, quiet=True, finish="effort")
    assert result.status == CONVERGED, result.message
    assert "finish (lower_effort): time limit reached" in result.message


def test_an_interrupted_finish_returns_and_keeps_its_best_step(monkeypatch, tmp_path):
    """Ctrl-C after the landing's first kept step: that step (it meets the goal, the search's
    result did not) is the result and the checkpoint's, the run says it was interrupted."""
    from casadi_keyframe.optimize import INTERRUPTED
    from casadi_keyframe.optimize.finish.window import WindowSearch

    real = WindowSearch.land

    def land_then_stop(self, rule):
        real(self, rule)
        raise KeyboardInterrupt

    monkeypatch.setattr(WindowSearch, "land", land_then_stop)
    prob = tight(swing())
    result = solve(prob, maxiter=50, quiet=True, finish="land",
                   checkpoint=tmp_path / "checkpoint.npz")
    assert result.status == INTERRUPTED, result.message
    assert "the finish was interrupted" in result.message
    assert result.breakdown["misses"][0]["rms_position_error"] <= 1e-3  # the landed step
    saved = np.load(tmp_path / "checkpoint.npz")
    np.testing.assert_array_equal(saved["u"], result.x)


def test_a_finish_that_ends_worse_returns_its_best_point(monkeypatch, tmp_path):
    """The landing's kept steps are offered as it goes; if what it returns is worse (here:
    zero forces, made up), the best point seen, a landed step, is the result and the
    checkpoint's, and the message says it is kept."""
    import time

    import casadi_keyframe.optimize.finish.stage as finish
    from casadi_keyframe.optimize.result import assemble

    real = finish.land

    def land_then_worse(problem, **kwargs):
        landed = real(problem, **kwargs)
        zero = np.zeros(problem.size)
        return assemble(problem, zero, fun=problem.objective(zero), jac=np.zeros(problem.size),
                        status=2, message="made worse", method="land", route=landed.route,
                        stages=landed.stages, history=[], started=time.perf_counter())

    monkeypatch.setattr(finish, "land", land_then_worse)
    prob = tight(swing())
    result = solve(prob, maxiter=50, quiet=True, finish="land",
                   checkpoint=tmp_path / "checkpoint.npz")
    assert result.status == CONVERGED, result.message
    assert "the finish's best step" in result.message and "is kept" in result.message
    assert result.breakdown["misses"][0]["rms_position_error"] <= 1e-3
    np.testing.assert_array_equal(np.load(tmp_path / "checkpoint.npz")["u"], result.x)
    assert result.fun == pytest.approx(prob.objective(result.x), rel=1e-9)
