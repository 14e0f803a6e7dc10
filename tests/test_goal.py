"""The animator's goal: keyframes declare tolerances (with defaults), a verdict names what is
missed and by how much, a third stage axis (homotopy) and SOLVE as a function of the start."""
import numpy as np
import pytest
from test_augmented_lagrangian import swing

from casadi_keyframe import (CenterOfMassKeyframe, RegionTarget, Smoothness, StateKeyframe,
                             load_problem)
from casadi_keyframe.loading import load_module, solve_defaults
from casadi_keyframe.optimize.goal import check_stop, has_goal, verdict
from casadi_keyframe.optimize.stages import stage_problems
from casadi_keyframe.shapes import Disc


def test_tolerances_default_to_a_hundredth_of_the_target_and_name_each_miss():
    prob = swing()
    key = prob.objective_terms.state_terms[0]
    extent = np.ptp(key.position_target, axis=0).max()
    assert key.within == (pytest.approx(0.01 * extent), None)  # no velocity target
    traj = prob.simulate()
    miss = key.miss(traj)["rms_position_error"]
    assert miss > key.within[0]
    assert key.shortfall(traj) == (f"{key.label}: rms position miss {miss:.3g} (tolerance "
                                   f"{key.within[0]:.3g})")
    found = verdict(prob, traj)
    assert not found.met and found.checked == 1 and found.misses == (key.shortfall(traj),)
    assert found.describe().startswith("still missed: StateKeyframe@10: rms position miss")


def test_every_keyframe_kind_declares_when_it_is_met():
    prob = swing()
    x = prob.objective_terms.state_terms[0].position_target
    idx = prob.objective_terms.state_terms[0].particles
    terms = (StateKeyframe(10, x=x, v=np.zeros_like(x), agents=idx, tolerance=(0.5, 1e-9))
             + CenterOfMassKeyframe(5, x=[0, 0, 0], tolerance=np.inf)
             + RegionTarget(10, Disc((0.0, 0.0), 100.0), fill=0.5) + Smoothness(1e-2))
    again = prob.with_objective(terms)
    state, center, region = again.objective_terms.state_terms
    assert state.within == (0.5, 1e-9) and center.within == (np.inf, None)
    assert not center.has_tolerance and region.has_tolerance and has_goal(again)
    traj = again.simulate()
    assert state.shortfall(traj).startswith("StateKeyframe@10: rms velocity miss")
    assert center.shortfall(traj) is None and region.shortfall(traj) is None
    off = prob.with_objective(CenterOfMassKeyframe(5, x=[0, 0, 0], tolerance=np.inf)
                              + Smoothness(1e-2))
    assert not has_goal(off) and check_stop(None, off) == "method"
    assert not verdict(off, traj).met and verdict(off, traj).checked == 0
    for bad in (0, -1, (1, 2, 3), "tight"):
        with pytest.raises(ValueError, match="tolerance"):
            StateKeyframe(3, x=[0, 0, 0], tolerance=bad)
    with pytest.raises(ValueError, match="fill is the fraction"):
        RegionTarget(3, Disc((0.0, 0.0), 1.0), fill=1.5)


def test_the_homotopy_solves_every_mesh_at_each_level_then_as_it_is():
    prob = load_problem("cloth_shapes", rows=4, cols=4, steps=12)
    stages = stage_problems(prob, [1 / 30], [{"rows": 3, "cols": 3}],
                            [{"strain_weight": 0.0}])
    assert [(p.model.n, p.steps) for p in stages] == [(9, 6), (9, 12), (9, 6), (9, 12),
                                                      (16, 6), (16, 12), (16, 6), (16, 12)]
    assert stages[-1] is prob
    assert not stages[4].objective_terms.trajectory_terms[0].weight  # the level's own model
    with pytest.raises(ValueError, match="a level changes the model, not the problem"):
        stage_problems(prob, None, None, [{"rows": 3}])
    with pytest.raises(ValueError, match="homotopy must be a list"):
        stage_problems(prob, None, None, {"contact": 3})


def test_solve_defaults_may_depend_on_the_start():
    module = load_module("cape_blend")
    assert "shooting" not in solve_defaults(module)
    assert solve_defaults(module, {"guess": "passive"})["shooting"]["segments"] > 1
