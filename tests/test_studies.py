"""The accuracy studies behind the notebooks and `casadi-keyframe study`, in quick mode."""
import numpy as np
import pytest

from casadi_keyframe.studies import accuracy as studies
from casadi_keyframe.cli import main
from casadi_keyframe.scenes.sheets import contact_problem


def test_fitted_order_recovers_a_power_law():
    h = np.array([0.1, 0.05, 0.025])
    assert studies.fitted_order(h, 3.0 * h ** 2.5) == pytest.approx(2.5)


def test_one_step_gap_shrinks_at_third_order_in_velocity():
    gap = studies.one_step_gap(dts=1 / 120 * 0.5 ** np.arange(4))
    assert np.all(np.diff(gap["gap_v"]) < 0) and np.all(np.diff(gap["gap_x"]) < 0)
    assert 2.5 < gap["slope_v"] < 3.5 and 3.3 < gap["slope_x"] < 4.5


def test_swapped_error_shrinks_with_dt_and_the_flock_control_is_exact():
    rows = [studies.swapped_vs_exact(dt) for dt in (1 / 30, 1 / 60, 1 / 120)]
    errors = [r["relative_error"] for r in rows]
    assert errors[0] > errors[1] > errors[2] and rows[1]["cosine"] > 0.99
    assert studies.flock_control_case(steps=8)["relative_error"] < 1e-10


def test_contact_problem_refuses_a_dt_that_does_not_divide_the_horizon():
    with pytest.raises(ValueError, match="whole number of steps"):
        contact_problem(dt=0.07)


@pytest.mark.parametrize("study, expect", [("gradient-accuracy", "fitted order in dt"),
                                           ("integrator-accuracy", "fitted slope, velocities")])
def test_study_command_prints_its_table(capsys, study, expect):
    assert main(["study", study, "--quick"]) == 0
    out = capsys.readouterr().out
    assert expect in out and "1/60" in out


def test_formulations_study_judges_each_run_by_its_replay(tmp_path):
    from casadi_keyframe.studies import formulations as f

    case, budget = f.Case(4), f.Budget(1, 120.0)
    good = f.Formulation("single shooting", "lbfgsb", "adjoint")
    bad = f.Formulation("no such option", "lbfgsb", options={"no_such_option": 1})
    rows = f.run_study([case], budget, tmp_path, formulations=(good, bad),
                       progress=lambda line: None)
    run, failed = rows
    assert run["exit"] in (0, 1, 3) and run["nit"] == 1 and run["cpu_seconds"] > 0
    assert run["peak_mb"] >= run["built_mb"] > 0
    assert run["tolerances_mm"] == pytest.approx([10.0, 10.0], rel=0.05)
    assert run["replay_mm"] < 1e-9 and run["reported_mm"] < 1e-9
    assert len(run["misses_mm"]) == 2 and min(run["misses_mm"]) > run["tolerances_mm"][0]
    assert "--method lbfgsb --gradient adjoint --maxiter 1" in run["command"]
    assert "error" in failed and "no_such_option" in (tmp_path / case.name /
                                                      f"{bad.name}.log").read_text()
    text = f.table(rows)
    assert "| single shooting | no such option |" in text and "failed" in text


def test_formulations_study_refuses_a_grid(capsys):
    assert main(["study", "formulations", "--grid", "dt=1/30"]) == 2
    assert "runs its own plan" in capsys.readouterr().err
