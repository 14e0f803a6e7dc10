"""No search returns a point worse than its start, judged by the goal first and then by the
objective, and no checkpoint is replaced by a worse one (issue 30)."""
import numpy as np
import pytest

from casadi_keyframe import CenterOfMassKeyframe, Smoothness, load_problem, solve
from casadi_keyframe.adjoints import Evaluation
from casadi_keyframe.optimize.evaluator import Evaluator
from casadi_keyframe.optimize.kept import Standing
from casadi_keyframe.optimize.goal import verdict
from casadi_keyframe.saved import Checkpoint, read_run


@pytest.fixture(scope="module")
def flock():
    prob = load_problem("flock_path", agents=6, steps=20, tolerance=2.0)
    best = solve(prob, maxiter=60, quiet=True, stop="method")
    return prob, best.x


def shifted(prob, by):
    """The same flock with every centre-of-mass target moved by ``by``."""
    terms = [CenterOfMassKeyframe(t.frame, x=t.position_target + by, position_weight=10.0,
                                  tolerance=2.0)
             for t in prob.objective_terms.state_terms]
    return prob.with_objective(sum(terms, Smoothness(1e-3)))


def judged(prob, u):
    traj = prob.simulate(u, records=False)
    return verdict(prob, traj).met, prob.objective(u)


def test_a_homotopy_that_ends_worse_returns_its_start_and_says_so(flock, tmp_path):
    prob, u_opt = flock
    ckpt = tmp_path / "checkpoint.npz"
    r = solve(prob, u0=u_opt, maxiter=3, quiet=True, stop="method", checkpoint=ckpt,
              homotopy=[shifted(prob, np.array([15.0, 15.0]))])
    assert judged(prob, u_opt)[0]  # the start meets the goal
    assert "its start" in r.message and "is kept" in r.message and r.success
    np.testing.assert_array_equal(r.x, u_opt)
    assert r.fun == pytest.approx(prob.objective(u_opt), rel=1e-12) == r.stages[-1]["fun"]
    assert [s["stage"] for s in r.stages] == list(range(len(r.stages)))
    assert r.stages[-2]["fun"] > r.fun  # the final stage's own best was worse
    np.testing.assert_array_equal(np.load(ckpt)["u"], u_opt)  # never replaced by a worse one


def test_the_result_is_never_worse_than_the_start_by_goal_then_objective(flock):
    prob, u_opt = flock
    start = np.zeros_like(u_opt)
    for homotopy in (None, [shifted(prob, np.array([3.0, -3.0]))]):
        r = solve(prob, u0=start, maxiter=4, quiet=True, homotopy=homotopy, stop="method")
        met, fun = judged(prob, r.x)
        met0, fun0 = judged(prob, start)
        assert (met, -fun) >= (met0, -fun0)
        assert r.fun == pytest.approx(r.stages[-1]["fun"], rel=1e-12)


class _Merit:
    """A merit that ranks a point by ``f`` and meets the goal where ``x[0] > 0``."""

    route = None

    def __call__(self, u):
        return Evaluation(float(u @ u), 2 * u)

    def meets(self, goal, info):
        return self.last[0] > 0

    def describe(self, u, f, info):
        return u, f, f, {}


def test_the_evaluator_keeps_a_point_that_meets_the_goal_over_a_lower_one(flock):
    prob, _ = flock
    merit = _Merit()
    ev = Evaluator(prob, None, None, merit=merit)
    for point in ([1.0, 0.0], [-0.5, 0.0], [0.5, 0.0]):  # meets, lower but misses, meets
        merit.last = np.array(point)
        ev(np.array(point))
    np.testing.assert_array_equal(ev.best_u, [0.5, 0.0])
    assert ev.best_met and ev.best_f == 0.25


def test_a_checkpoint_takes_only_points_at_least_as_good(tmp_path):
    ckpt = Checkpoint(tmp_path / "c.npz", problem="p")
    wrote = [ckpt.write(np.array([k]), Standing(m, f), final=final, stage=s)
             for k, (f, m, final, s) in enumerate([
                 (5.0, False, False, 0),   # a coarse stage's point
                 (9.0, False, False, 1),   # a later coarse stage wins whatever its objective
                 (3.0, False, True, 2),    # the final problem beats any coarse stage
                 (1.0, False, False, 3),   # a coarse point never replaces a final one
                 (4.0, True, True, 2),     # meeting the goal beats a lower objective
                 (2.0, False, True, 2),    # missing it never replaces one that meets it
                 (3.5, True, True, 2)])]   # then the lower objective
    assert wrote == [True, True, True, False, True, False, True]
    assert read_run(tmp_path / "c.npz")["u"].tolist() == [6.0]
    later = ckpt.with_meta(generation=1, rounds_round=1)  # a later round of hard keyframes
    assert later.write(np.array([7]), Standing(True, 8.0)) and not later.write(
        np.array([8]), Standing(False, 1.0))
    assert read_run(tmp_path / "c.npz")["meta"]["rounds_round"] == 1


@pytest.mark.parametrize("extra", [["--set", "steps=16", "--continuation", "1/10"],
                                   ["--segments", "2", "--shooting", "rounds=2"]])
def test_one_story_per_run(extra, tmp_path, capsys):
    """The objective printed, in summary.json, the last stage's, the history's last and the
    one recomputed from result.npz are one number; stages have distinct numbers."""
    import json

    from casadi_keyframe.cli import main
    from casadi_keyframe.saved import load_saved

    out = tmp_path / "run"
    main(["solve", "flock_path", "--set", "agents=6", "--set", "steps=20", "--set",
          "tolerance=2.0", "--maxiter", "4", "--quiet", "--no-animation", "--no-viewer",
          "--out", str(out), *extra])
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    saved = load_saved(out)
    again = saved.problem.objective(np.load(out / "result.npz")["u"])
    assert summary["fun"] == pytest.approx(summary["stages"][-1]["fun"], rel=1e-9)
    assert summary["fun"] == pytest.approx(again, rel=1e-9)
    assert f"objective {summary['fun']:.6g}" in printed
    history = np.load(out / "result.npz")["history_objective"]
    assert history[-1] == pytest.approx(summary["fun"], rel=1e-9)
    numbers = [s["stage"] for s in summary["stages"]]
    assert numbers == sorted(set(numbers))
    assert summary["nfev"] == sum(s["nfev"] for s in summary["stages"])
    effort = summary["breakdown"]["effort"]
    assert effort == saved.problem.effort(np.load(out / "result.npz")["u"])
    assert f"effort: rms {effort['rms_acceleration']:.3g} m/s^2" in printed


def test_a_stage_that_meets_the_goal_counts_its_own_iterations_and_the_runs():
    """Stage messages give the run's iteration and the stage's own count, matching ``nit``."""
    prob = load_problem("flock_path", agents=6, steps=40, tolerance=2.0)
    result = solve(prob, maxiter=60, quiet=True, continuation=[prob.dt * 5])
    total = 0
    for stage in result.stages:
        total += stage["nit"]
        assert (f"the goal is met at iteration {total}, {stage['nit']} in this stage"
                in stage["message"]), stage["message"]


def test_effort_is_the_control_forces_over_the_pushed_particles_masses(flock):
    """rms over controlled particles and steps, and the peak, of |force| / mass; none for
    initial-velocity controls."""
    prob, u = flock
    forces = prob.controls.external(u)[:, prob.controls.idx]
    acc = np.linalg.norm(forces, axis=-1) / prob.model.masses[prob.controls.idx]
    effort = prob.effort(u)
    assert effort["rms_acceleration"] == pytest.approx(np.sqrt((acc ** 2).mean()))
    assert effort["peak_acceleration"] == acc.max() > effort["rms_acceleration"]
    toss = load_problem("cloth_toss", rows=4, cols=4)
    assert toss.effort(toss.initial_controls()) is None
    assert "effort" not in toss.breakdown(toss.initial_controls())
