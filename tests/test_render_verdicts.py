"""Pictures that judge: each keyframe panel says HIT or MISSED exactly as the search's goal
does, with the miss beside its tolerance; every keyframe of a flock gets its panel; the
colour bar of the distance is the problem's, whatever the trajectory; a search that took no
iteration still gets its convergence picture."""
import importlib
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest

from casadi_keyframe import ControlProblem, StateKeyframe, StepForces, load_problem
from casadi_keyframe.integrators import LinearizedBackwardEuler
from casadi_keyframe.models import ClothModel
from casadi_keyframe.objectives import CenterOfMassKeyframe, ParticleKeyframe
from casadi_keyframe.optimize.goal import verdict
from casadi_keyframe.render import cloth as render_cloth
from casadi_keyframe.render import flock as render_flock
from casadi_keyframe.render.targets import TOLERANCES_SHOWN, distance_colors
from casadi_keyframe.render.verdicts import check_text

render_convergence = importlib.import_module("casadi_keyframe.render.convergence")  # the module


def _kept(monkeypatch, module):
    """Make ``module``'s pictures keep their figure instead of writing it."""
    kept = []
    monkeypatch.setattr(module, "save_figure", lambda fig, path, **kw: kept.append(fig))
    monkeypatch.setattr(module.plt, "close", lambda fig=None: None)
    return kept


def _said(fig) -> dict:
    """``{frame: [label text, ...]}`` of every panel of ``fig`` titled with its frame."""
    out = {}
    for ax in fig.axes:
        title = ax.get_title().split(": ")[-1]
        if ax.get_visible() and title.startswith("frame "):
            out.setdefault(int(title.split()[1]), []).extend(t.get_text() for t in ax.texts)
    return out


def _agrees_with_the_goal(problem, trajectory, said) -> set:
    """Assert each keyframe's label is HIT exactly when the goal finds it met; the verdicts."""
    missed = {m.split(":")[0] for m in verdict(problem, trajectory).misses}
    seen = set()
    for term in problem.objective_terms.state_terms:
        labels = [t for t in said[term.frame] if t.split()[1].rstrip(":") == term.label]
        assert len(labels) == 1, (term.label, said[term.frame])
        word = labels[0].split()[0]
        assert word == ("MISSED" if term.label in missed else "HIT"), labels[0]
        seen.add(word)
    return seen


@pytest.fixture(scope="module")
def sheet():
    """A 4 x 4 hanging sheet whose passive motion (the search's start) meets two keyframes
    (frame 3's shape, frame 5's centre of mass) and misses two (frame 6 lowered 5 cm, a
    corner at frame 5 far off)."""
    model = ClothModel.grid(4, 4, pinned=[0, 3])
    x0 = model.rest_positions

    def problem(objective):
        return ControlProblem(model=model, integrator=LinearizedBackwardEuler(), x0=x0,
                              v0=np.zeros_like(x0), steps=6, dt=1 / 30, controls=StepForces(),
                              objective=objective, name="sheet")

    passive = problem(StateKeyframe(6, x=x0)).simulate()
    com = model.masses @ passive.x[5] / model.masses.sum()
    prob = problem(StateKeyframe(3, x=passive.x[3])
                   + StateKeyframe(6, x=passive.x[6] - [0, 0, 0.05])
                   + CenterOfMassKeyframe(5, x=com)
                   + ParticleKeyframe(5, [15], x=[passive.x[5, 15] + 1.0]))
    return prob, passive


def test_a_cloth_panel_says_hit_exactly_when_the_goal_does(sheet, tmp_path, monkeypatch):
    prob, start = sheet
    kept = _kept(monkeypatch, render_cloth)
    render_cloth.snapshot(prob, start, tmp_path / "k.png")
    said = _said(kept[0])
    assert _agrees_with_the_goal(prob, start, said) == {"HIT", "MISSED"}
    assert sorted(said) == [0, 3, 5, 6] and said[0] == []  # each keyframe, and the start
    assert "rms miss 50 mm (tol" in " ".join(said[6])  # in mm, with its tolerance
    assert "centre-of-mass miss" in " ".join(said[5])
    assert kept[0]._suptitle.get_text() == "sheet: 2 of 4 keyframes hit"


def test_every_keyframe_of_a_flock_gets_its_panel_and_its_verdict(tmp_path, monkeypatch):
    """flock_path with 4 keyframes: 4 keyframe panels (and the start's), each judged as the
    goal judges it; its tolerance set between the passive misses so some hit, some miss."""
    small = {"agents": 6, "steps": 20, "keyframes": 4}
    passive = load_problem("flock_path", **small)
    start = passive.simulate()
    misses = [t.miss(start)["position_error"] for t in passive.objective_terms.state_terms]
    prob = load_problem("flock_path", tolerance=float(np.median(misses)), **small)
    kept = _kept(monkeypatch, render_flock)
    render_flock.snapshot(prob, start, tmp_path / "k.png")
    said = _said(kept[0])
    assert sorted(said) == [0, 5, 10, 15, 20]
    assert [len(said[f]) for f in (5, 10, 15, 20)] == [1, 1, 1, 1]
    assert _agrees_with_the_goal(prob, start, said) == {"HIT", "MISSED"}
    assert all("centre-of-mass miss" in said[f][0] and "(tol " in said[f][0]
               for f in (5, 10, 15, 20))


def test_a_keyframe_on_velocities_alone_is_judged_in_cm_per_s(sheet):
    prob, start = sheet
    term = StateKeyframe(4, v=start.v[4] + [0.0, 0.0, 0.3]).bind(prob.model, prob.steps)
    marker = term.marker()
    check = marker.check(start)
    assert marker.kind.name == "velocity" and marker.points.shape == (0, 3)
    assert check.met is (term.shortfall(start) is None) and check.met is False
    assert check_text(check, metres=True).startswith(
        "MISSED  StateKeyframe@4: velocity rms miss 30 cm/s (tol")


def _bar(fig):
    bars = [ax for ax in fig.axes if "distance" in ax.get_xlabel()]
    assert len(bars) == 1
    return bars[0]


def test_the_colour_bar_is_the_problems_whatever_the_trajectory(sheet, tmp_path,
                                                                 monkeypatch):
    prob, start = sheet
    pushed = prob.simulate(np.random.default_rng(0).normal(0, 2.0, prob.initial_controls().size))
    kept = _kept(monkeypatch, render_cloth)
    render_cloth.snapshot(prob, start, tmp_path / "a.png")
    render_cloth.snapshot(prob, pushed, tmp_path / "b.png")
    render_cloth.side_by_side(prob, {"start": start, "result": pushed}, tmp_path / "c.png")
    tightest = min(t.within[0] for t in prob.objective_terms.state_terms
                   if isinstance(t, StateKeyframe))
    top = TOLERANCES_SHOWN * 1e3 * tightest
    for fig in kept:
        bar = _bar(fig)
        assert bar.get_xlim() == pytest.approx((0.0, top))
        marks = [line.get_xdata()[0] for line in bar.lines]
        assert marks and marks[0] == pytest.approx(1e3 * tightest)  # the tolerance, marked
        assert "clipped" in bar.get_xlabel()
    fig = plt.figure()
    panels = [render_cloth.TrajectoryPanel(fig.add_subplot(projection="3d"), prob, t)
              for t in (start, pushed)]  # the animation's
    assert panels[0].scale == panels[1].scale
    far = distance_colors([top, 10 * top], panels[0].scale)
    assert np.array_equal(far[0], far[1])  # farther than the bar: its top colour
    plt.close(fig)


def test_a_search_that_took_no_iteration_draws_its_start(tmp_path, monkeypatch):
    kept = _kept(monkeypatch, render_convergence)
    result = SimpleNamespace(history=[], start={"objective": 2e-3, "keyframe_error": 1e-3},
                             method="lbfgsb", gradient="adjoint")
    render_convergence.convergence(result, tmp_path / "c.png")
    left = kept[0].axes[0]
    objective = next(line for line in left.lines if line.get_label() == "objective")
    assert list(objective.get_xdata()) == [0] and list(objective.get_ydata()) == [2e-3]
    assert objective.get_marker() == "o"
    assert any("no iterations" in t.get_text() for t in kept[0].texts)
