"""Every producer of a Result (solve, solve_augmented, lower_effort) fills the same typed
records, and a Result that lacks one of their keys is refused when it is made: what
summary.json, result.npz and the convergence plot read is always there."""
import json

import numpy as np
import pytest
from test_augmented_lagrangian import swing

from casadi_keyframe.saved import save_result
from casadi_keyframe.optimize import lower_effort, solve, solve_augmented
from casadi_keyframe.optimize.result import (HistoryRecord, Result, Stage, Timings,
                                             history_record)
from casadi_keyframe.render.convergence import convergence


@pytest.fixture(scope="module")
def results():
    prob = swing()
    plain = solve(prob, maxiter=8, quiet=True, stop="method")
    rounds = solve_augmented(prob, rounds=3, maxiter=30, quiet=True, stop="method")
    # its landing with wasted effort: kicks whose second difference leaves the landing be
    u = rounds.x.reshape(prob.steps, -1, 3).copy()
    kick = 0.2 * np.random.default_rng(0).standard_normal(u.shape[1:])
    u[3] += kick
    u[4] -= 2 * kick
    u[5] += kick
    held = lower_effort(prob, u0=u.ravel(), position_tolerance=0.01, velocity_tolerance=1.0,
                        maxiter=2)
    return prob, u.ravel(), {"solve": plain, "solve_augmented": rounds, "lower_effort": held}


def test_every_producer_fills_the_same_records(results):
    prob, start, by_producer = results
    for name, r in by_producer.items():
        assert set(r.timings) == set(Timings.__annotations__), name
        assert r.stages and all(Stage.__required_keys__ <= set(s) for s in r.stages), name
        assert r.history and r.nit == len(r.history), name
        for h in r.history:
            assert HistoryRecord.__required_keys__ <= set(h), name
            assert np.isfinite([h["objective"], h["keyframe_error"], h["seconds"]]).all()
        assert r.nfev == sum(s["nfev"] for s in r.stages), name
        assert 0 < r.njev == sum(s["njev"] for s in r.stages), name
        assert np.isfinite(r.start["objective"]) and np.isfinite(r.start["keyframe_error"])
        assert r.summary()["njev"] == r.njev


def test_lower_effort_records_its_objective_at_each_kept_step(results):
    prob, start, by_producer = results
    held = by_producer["lower_effort"]
    assert held.nit >= 1 and held.method == "lower_effort"
    last = held.history[-1]  # the last kept step is the result
    assert last["objective"] == pytest.approx(held.fun, rel=1e-9)
    assert last["control_cost"] == pytest.approx(held.breakdown["control_cost"], rel=1e-12)
    assert last["keyframe_error"] == pytest.approx(held.fun - last["control_cost"], rel=1e-9)
    assert held.start["objective"] == pytest.approx(prob.objective(start), rel=1e-9)
    assert last["control_cost"] < prob.control_cost(start)[0]  # the wasted effort is gone


def test_the_saved_result_and_its_plot_read_every_producer(results, tmp_path):
    _, _, by_producer = results
    for name, r in by_producer.items():
        summary = save_result(r, tmp_path / name, problem_name="swing")
        on_disk = json.loads((tmp_path / name / "summary.json").read_text())
        assert on_disk["nit"] == r.nit and on_disk["njev"] == r.njev == summary["njev"]
        with np.load(tmp_path / name / "result.npz") as saved:
            objective = saved["history_objective"]
        assert objective.shape == (r.nit,) and np.isfinite(objective).all()
        assert convergence(r, tmp_path / f"{name}.png").stat().st_size > 0


def test_a_result_missing_a_key_is_refused_by_name(results):
    prob, start, by_producer = results
    r = by_producer["solve"]
    fields = {**vars(r)}
    bare = {k: v for k, v in r.history[0].items() if k != "objective"}
    with pytest.raises(ValueError, match="history record 0 lacks objective"):
        Result(**{**fields, "history": [bare]})
    with pytest.raises(ValueError, match="timings lacks evaluation_seconds"):
        Result(**{**fields, "timings": {"wall_seconds": 1.0, "failed_simulations": 0,
                                        "stage_seconds": [1.0]}})
    with pytest.raises(ValueError, match="stage 0 lacks njev"):
        Result(**{**fields, "stages": [{k: v for k, v in r.stages[0].items() if k != "njev"}]})
    with pytest.raises(ValueError, match="success status == 0"):
        Result(**{**fields, "status": 2, "success": True})
    with pytest.raises(ValueError, match="has undeclared colour"):
        history_record(prob, r.x, objective=1.0, keyframe_error=0.5, iteration=1, stage=0,
                       seconds=0.0, nfev=1, colour="red")
