"""Rendering: files are written, frames are chosen well, empty histories are handled."""
import dataclasses

import numpy as np
import pytest
from PIL import Image

from casadi_keyframe import render
from casadi_keyframe.controls import StepForces
from casadi_keyframe.integrators import SymplecticEuler
from casadi_keyframe.models import FlockModel, FlockParams
from casadi_keyframe.objectives import (CenterOfMassKeyframe, ParticleKeyframe, RegionTarget,
                                        Smoothness, StateKeyframe)
from casadi_keyframe.optimize import solve
from casadi_keyframe.problem import ControlProblem
from casadi_keyframe.shapes import cross, square
from casadi_keyframe.views import FlockView

KEYS = (13, 27, 33, 40)


def _problem(dim=2, highlight=(0,)):
    """8 agents, 40 steps, every kind of keyframe; positions padded with zeros in 3-D."""
    rng = np.random.default_rng(0)
    n, pad = 8, [0.0] * (dim - 2)
    objective = (CenterOfMassKeyframe(13, x=[3, 0] + pad) + CenterOfMassKeyframe(33, x=[4, 2] + pad)
                 + RegionTarget(27, square((4, 2), 3)) + RegionTarget(40, cross((2, 5), 4, 1.5))
                 + ParticleKeyframe(40, [0], x=[[2, 6] + pad])
                 + StateKeyframe(40, agents=[1], v=[[0.0] * dim]) + Smoothness(1e-3))
    return ControlProblem(model=FlockModel(rng.uniform(0.5, 2, n), dim, FlockParams()),
                          integrator=SymplecticEuler(), x0=rng.uniform(0, 2, (n, dim)),
                          v0=np.zeros((n, dim)), steps=40, dt=0.1, controls=StepForces(),
                          objective=objective, name=f"render-{dim}d",
                          view=FlockView(highlight=highlight))


@pytest.fixture(scope="module")
def solved():
    p = _problem()
    return p, solve(p, "lbfgsb", maxiter=3, quiet=True)


def test_keyframes_listed():
    assert render.keyframes(_problem()) == list(KEYS)


@pytest.mark.parametrize("steps,max_frames", [(40, 10), (300, 150), (1000, 7), (41, 40)])
def test_select_frames_keeps_keyframes_and_ends(steps, max_frames):
    keys = [k for k in (3, 13, 27, 33, 40, steps // 2 + 1) if k <= steps]
    frames = render.select_frames(steps, keys, max_frames)
    assert frames == sorted(set(frames))
    assert frames[0] == 0 and frames[-1] == steps
    assert set(keys) <= set(frames)
    assert len(frames) == max_frames + 1


def test_select_frames_evenly_spaced():
    gaps = np.diff(render.select_frames(1000, [501], 10))
    assert gaps.max() <= 101 and gaps.min() >= 99


def test_select_frames_short_trajectory_keeps_all():
    assert render.select_frames(20, [5], 150) == list(range(21))
    assert render.select_frames(10, [], 10) == list(range(11))


def test_select_frames_more_keyframes_than_budget():
    keys = list(range(5, 100, 5))
    assert render.select_frames(100, keys, 4) == [0] + keys + [100]


def test_animate_writes_gif_with_keyframes(solved, tmp_path):
    p, r = solved
    out = render.animate(p, r.trajectory, tmp_path / "flock.gif", fps=10, max_frames=10,
                         title="custom")
    assert out == tmp_path / "flock.gif" and out.stat().st_size > 0
    expected = render.select_frames(r.trajectory.steps, render.keyframes(p), 10)
    assert set(KEYS) <= set(expected) and len(expected) == 11
    with Image.open(out) as im:
        assert im.n_frames == len(expected)


def test_snapshot_and_convergence_write_png(solved, tmp_path):
    p, r = solved
    for out in (render.snapshot(p, r.trajectory, tmp_path / "snap.png"),
                render.snapshot(p, r.trajectory, tmp_path / "two.png", frames=[0, 40]),
                render.convergence(r, tmp_path / "conv.png")):
        assert out.stat().st_size > 0
        with Image.open(out) as im:
            assert im.format == "PNG"
    with pytest.raises(ValueError):
        render.snapshot(p, r.trajectory, tmp_path / "bad.png", frames=[0, 99])


def test_convergence_empty_history(solved, tmp_path):
    empty = dataclasses.replace(solved[1], history=[])
    out = render.convergence(empty, tmp_path / "empty.png")
    assert out.exists() and out.stat().st_size > 0


def test_three_d_without_highlight(tmp_path):
    p = _problem(dim=3, highlight=())
    traj = p.simulate()
    assert render.snapshot(p, traj, tmp_path / "s3.png").stat().st_size > 0
    with Image.open(render.animate(p, traj, tmp_path / "a3.gif", max_frames=5)) as im:
        assert im.n_frames == 6


def test_the_convergence_plot_starts_at_the_starting_point(tmp_path):
    import matplotlib.pyplot as plt
    """Iteration 0 is the start, so a plot shows what the search did from where it began."""
    from casadi_keyframe import load_problem, solve
    from casadi_keyframe.render import convergence

    prob = load_problem("flock_path", agents=6, steps=20)
    result = solve(prob, maxiter=3, quiet=True)
    assert result.start["objective"] == pytest.approx(prob.objective(prob.initial_controls()))
    assert result.start["keyframe_error"] <= result.start["objective"]  # no control cost yet
    drawn = []
    real = plt.Axes.plot

    def spy(ax, x, y, *args, **kw):
        drawn.append((list(x), list(y)))
        return real(ax, x, y, *args, **kw)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt.Axes, "plot", spy)
        convergence(result, tmp_path / "c.png")
    x, y = drawn[0]
    assert x[0] == 0 and y[0] == pytest.approx(result.start["objective"])
    assert len(x) == result.nit + 1
