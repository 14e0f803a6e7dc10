"""The swap-validity map (issue 25): its points measure what they say, its slices cover the
issue's ranges, and it runs on the sweep runner, each point once."""
import json

import numpy as np
import pytest

from casadi_keyframe.cli import main
from casadi_keyframe.studies.accuracy import fitted_order
from casadi_keyframe.studies.swap_validity import (KINDS, format_swap_validity, map_points,
                                           one_step_error, sheet_problem,
                                           swap_validity_point)


def test_without_contact_the_swap_is_close_and_near_a_sliding_capsule_it_grows():
    free = swap_validity_point("none", stiffness=1.0, rows=4)
    assert free["cosine"] > 0.99 and free["touching"] == 0 and not free["refused"]
    assert free["growth_swapped"] == pytest.approx(free["growth_exact"], rel=0.1)
    capsule = swap_validity_point("capsule", collision="penalty", stiffness=7.0, horizon=1.0,
                                  rows=4)
    assert capsule["touching"] > 0.2  # it does slide over the capsule
    assert capsule["growth_exact"] < 100 < 1e3 < capsule["growth_swapped"]
    assert capsule["cosine"] < 0.5


def test_one_swapped_step_errs_at_third_order_in_dt_without_contact():
    dts = [1 / 240, 1 / 480, 1 / 960]
    free = [one_step_error("none", stiffness=1.0, dt=dt, rows=4)["local_error"] for dt in dts]
    folded = [one_step_error("self", stiffness=1.0, dt=dt, rows=4)["local_error"] for dt in dts]
    assert fitted_order(dts, free) > 2.5  # the paper's O(dt^3)
    assert 1.5 < fitted_order(dts, folded) < 2.5  # self-contact: one order short


def test_every_contact_kind_touches_what_it_names():
    for kind in KINDS:
        prob = sheet_problem(kind, rows=4)
        traj = prob.simulate()
        if kind == "self":
            assert all(prob.model.interactions(x)[-1][0].size for x in traj.x)
        else:
            assert len(prob.model.colliders) == (kind != "none")


def test_the_map_spans_the_issues_ranges():
    slices = map_points(quick=False)
    stiffness = {p["stiffness"] for p in slices["stiffness"]}
    assert min(stiffness) == 0.5 and max(stiffness) == 10
    assert {p["contact"] for p in slices["stiffness"]} == set(KINDS)
    assert {(p["contact"], p["collision"]) for p in slices["stiffness"]} >= {
        ("sphere", "penalty"), ("capsule", "guarded"), ("capsule", "penalty")}
    assert all(p["solve"] for p in slices["stiffness"])
    assert len({p["dt"] for p in slices["dt"]}) >= 3
    assert len({p["amplitude"] for p in slices["amplitude"]}) >= 3


def test_the_optimizer_comparison_and_its_table():
    row = {**map_points(quick=True)["stiffness"][0]}
    row.update(swap_validity_point(**{**row, "maxiter": 3}))
    assert row["objective_adjoint"] < row["start_objective"]
    assert row["reaches"] in (True, False)
    study = {name: [row] for name in ("stiffness", "dt")}
    study["order"] = {"none guarded": np.nan}
    text = format_swap_validity(study)
    assert "reaches" in text and "none: cosine 1.00 at 0-2" in text and "1 of 1" in text


def test_the_study_runs_a_grid_of_it_on_the_sweep_runner(tmp_path):
    out = tmp_path / "map"
    assert main(["study", "swap-validity", "--grid", "stiffness=1,2", "--set", "rows=3",
                 "--set", "horizon=0.1", "--out", str(out), "--workers", "1",
                 "--quiet"]) == 0
    rows = [json.loads(p.read_text()) for p in out.glob("points/*/row.json")]
    assert sorted(r["stiffness"] for r in rows) == [1, 2]
    assert all(r["steps"] == 6 and 0.9 < r["cosine"] <= 1 for r in rows)


def test_a_map_of_slices_runs_each_point_once_on_the_runner(tmp_path):
    from casadi_keyframe.studies.sweeps import study_points

    tiny = {**map_points(quick=True)["dt"][0], "rows": 3, "horizon": 0.1, "dt": 1 / 60}
    points = [tiny, {**tiny, "stiffness": 2.0}, dict(tiny)]  # the last repeats the first
    result = study_points("swap-validity", points, out=tmp_path, workers=1, progress=False)
    assert result.exit_code == 0 and len(result.rows) == 2
    assert len(list(tmp_path.glob("points/*/row.json"))) == 2
