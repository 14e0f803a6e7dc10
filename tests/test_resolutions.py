"""Coarse to fine in space: controls carried between meshes of the same cloth (closest point
on the rest mesh, linear fields reproduced, momentum and impulse kept), solve(resolutions=)
stages, and the refusals."""
import json

import numpy as np
import pytest
from scipy.spatial import Delaunay

from casadi_keyframe import load_problem, solve
from casadi_keyframe.models import ClothModel
from casadi_keyframe.optimize.transfer import _closest_on_triangles, carry_to_mesh, mesh_interpolation

from helpers import InterruptAfter


def test_closest_points_match_a_dense_search():
    rng = np.random.default_rng(0)
    tri = rng.standard_normal((200, 3, 3))
    p = 2 * rng.standard_normal((200, 3))
    weights, dist2 = _closest_on_triangles(p, tri)
    assert np.all(weights >= -1e-12) and np.allclose(weights.sum(-1), 1)
    closest = np.einsum("mc,mcd->md", weights, tri)
    np.testing.assert_allclose(np.sum((closest - p) ** 2, -1), dist2, rtol=1e-10)
    a, b = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
    keep = a + b <= 1
    bary = np.stack([1 - a[keep] - b[keep], a[keep], b[keep]], -1)  # a dense triangle sample
    samples = np.einsum("sc,mcd->msd", bary, tri)
    dense = np.min(np.sum((samples - p[:, None]) ** 2, -1), axis=1)
    assert np.all(dist2 <= dense + 1e-12)  # never farther than the samples
    assert np.all(dist2 >= dense - 0.02 * np.sqrt(dense) - 1e-4)  # and close to the best


def test_interpolation_reproduces_linear_fields_on_an_irregular_mesh():
    rng = np.random.default_rng(1)
    pts = np.vstack([[[0, 0], [1, 0], [0, 1], [1, 1]], rng.uniform(0, 1, (30, 2))])
    coarse = np.c_[pts, np.zeros(len(pts))]
    faces = Delaunay(pts).simplices
    fine = ClothModel.grid(9, 7, plane="xy").rest_positions
    P = mesh_interpolation(coarse, faces, fine)
    assert P.shape == (len(fine), len(coarse)) and np.diff(P.indptr).max() <= 3
    np.testing.assert_allclose(P.sum(axis=1).A.ravel(), 1, atol=1e-12)
    A, b = rng.standard_normal((3, 4)), rng.standard_normal(4)
    np.testing.assert_allclose(P @ (coarse @ A + b), fine @ A + b, atol=1e-12)
    lifted = fine + [0, 0, 0.3]  # off the surface: the point below it
    np.testing.assert_allclose((P - mesh_interpolation(coarse, faces, lifted)).data, 0,
                               atol=1e-12)


def toss(rows, steps=12):
    """The toss's first flight (keyframes at frames 16 and 28 of 30: even, on 2 dt's grid)."""
    return load_problem("cloth_toss", rows=rows, cols=rows, steps=steps, ring_at=0.52,
                        flip_at=0.94)


def shapes(rows, steps=12):
    return load_problem("cloth_shapes", rows=rows, cols=rows, steps=steps)


def test_initial_velocities_carry_a_rigid_motion_exactly_and_keep_momentum():
    coarse, fine = toss(4), toss(9)
    centre = coarse.model.rest_positions.mean(0)
    spin = np.cross([0.0, 3.0, 1.0], coarse.model.rest_positions - centre) + [0.5, 0, 0]
    u = carry_to_mesh(coarse, spin.ravel(), fine)
    expected = np.cross([0.0, 3.0, 1.0], fine.model.rest_positions - centre) + [0.5, 0, 0]
    np.testing.assert_allclose(u.reshape(-1, 3), expected, atol=1e-12)
    rough = np.random.default_rng(2).standard_normal(coarse.size)
    moved = carry_to_mesh(coarse, rough, fine).reshape(-1, 3)
    momentum = coarse.model.masses @ rough.reshape(-1, 3)
    np.testing.assert_allclose(fine.model.masses @ moved, momentum, atol=1e-12)


def test_step_forces_keep_every_steps_total_force_and_the_impulse_in_time():
    coarse, fine = shapes(4), shapes(7, steps=24)  # another mesh and twice the steps
    assert fine.controls.idx.size < fine.model.n  # some particles are not controlled
    u = np.random.default_rng(3).standard_normal(coarse.size)
    moved = carry_to_mesh(coarse, u, fine)
    controlled = [p.model.masses[p.controls.idx].sum() for p in (coarse, fine)]
    assert controlled[0] != pytest.approx(controlled[1])  # so the totals scale with it
    total = u.reshape(12, -1, 3).sum(1) * controlled[1] / controlled[0]
    carried = moved.reshape(24, -1, 3).sum(1)
    np.testing.assert_allclose(carried[0::2], total, atol=1e-12)
    np.testing.assert_allclose(carried[1::2], total, atol=1e-12)
    # the same acceleration field on both meshes: a uniform one stays uniform
    weight = coarse.model.masses[coarse.controls.idx, None] * [0.0, 0.0, 2.0]
    uniform = carry_to_mesh(coarse, np.tile(weight, (12, 1, 1)).ravel(), fine)
    np.testing.assert_allclose(uniform.reshape(24, -1, 3),
                               np.broadcast_to(fine.model.masses[fine.controls.idx, None]
                                               * [0.0, 0.0, 2.0], (24, fine.controls.idx.size,
                                                                    3)), atol=1e-12)


def test_carrying_refuses_what_it_does_not_know():
    with pytest.raises(ValueError, match="per-step forces and initial velocities of the same"):
        carry_to_mesh(toss(3), np.zeros(27), shapes(4))
    flock = load_problem("flock_race", agents=6, steps=12, keyframes=2)
    with pytest.raises(ValueError, match="has no mesh"):
        carry_to_mesh(flock, flock.initial_controls(), load_problem("flock_race", agents=8,
                                                                    steps=12, keyframes=2))


def test_solve_goes_coarse_to_fine_and_names_each_mesh(tmp_path):
    prob = toss(6, steps=30)  # keyframes at frames 16 and 28: on the grid of 2 dt too
    r = solve(prob, maxiter=6, quiet=True, resolutions=[{"rows": 3, "cols": 3}],
              continuation=[2 * prob.dt], checkpoint=tmp_path / "best.npz")
    assert [(s["particles"], s["steps"]) for s in r.stages] == [(9, 15), (9, 30), (36, 15),
                                                                 (36, 30)]
    assert {h["particles"] for h in r.history if h["stage"] == 3} == {36}
    assert r.x.size == prob.size and r.fun == pytest.approx(prob.objective(r.x), rel=1e-12)
    assert np.load(tmp_path / "best.npz")["u"].size == prob.size


def test_the_fine_mesh_starts_from_the_coarse_best_carried():
    prob = toss(6)
    coarse = prob.at_resolution(rows=3, cols=3)
    r = solve(prob, maxiter=6, quiet=True, resolutions=[coarse])
    alone = solve(coarse, maxiter=6, quiet=True)  # the same deterministic search
    assert alone.fun == pytest.approx(r.stages[0]["fun"], rel=1e-12)
    start = prob.objective(carry_to_mesh(coarse, alone.x, prob))
    assert r.stages[1]["start_objective"] == pytest.approx(start, rel=1e-12)
    assert start < prob.objective(prob.initial_controls())  # the coarse work carries over


def test_an_interrupt_on_a_coarse_mesh_keeps_its_best_on_the_fine_one():
    prob = toss(6)
    r = solve(prob, gradient=InterruptAfter(5), maxiter=50, quiet=True,
              resolutions=[prob.at_resolution(rows=3, cols=3)])
    assert "in stage 0 (9 particles" in r.message and "interrupted" in r.message
    assert r.x.size == prob.size and r.trajectory.x.shape[1] == 36


def test_a_mesh_no_coarser_than_the_problem_is_left_out_and_said():
    """A "coarse" stage as fine as the problem would solve it twice: it is not run, and its
    stage says why."""
    r = solve(toss(6), maxiter=2, quiet=True, resolutions=[{"rows": 6, "cols": 6},
                                                           {"rows": 3, "cols": 3}])
    assert [s["particles"] for s in r.stages] == [36, 9, 36]
    left_out = r.stages[0]
    assert left_out["skipped"] == "nothing to do" and left_out["nit"] == left_out["nfev"] == 0
    assert "no fewer than the problem's 36" in left_out["message"]
    assert "overrides" not in left_out and r.stages[1]["overrides"] == {"rows": 3, "cols": 3}


@pytest.mark.parametrize("resolutions, match", [
    ([{"rows": 4, "cols": 4}, {"rows": 3, "cols": 3}], "coarse to fine"),
    ([{"steps": 24}], "not the same problem"),
    ({"rows": 3}, "must be a list"),
    (["3x3"], "neither a problem nor a dict")])
def test_bad_resolutions_are_refused_with_the_fix(resolutions, match):
    with pytest.raises(ValueError, match=match):
        solve(toss(6), maxiter=1, quiet=True, resolutions=resolutions)


def test_a_changed_problem_cannot_be_rebuilt():
    prob = toss(6)
    changed = prob.with_objective(prob.objective_terms)
    with pytest.raises(ValueError, match="build the coarser problems yourself"):
        solve(changed, maxiter=1, quiet=True, resolutions=[{"rows": 3, "cols": 3}])
    r = solve(changed, maxiter=2, quiet=True, resolutions=[prob.at_resolution(rows=3, cols=3)])
    assert [s["particles"] for s in r.stages] == [9, 36]


def test_cli_solves_coarse_to_fine(tmp_path, capsys):
    from casadi_keyframe.cli import main

    code = main(["solve", "cloth_toss", "--set", "rows=5", "--set", "cols=5", "--set",
                 "steps=12", "--resolution", "rows=3,cols=3", "--maxiter", "3", "--quiet",
                 "--no-animation", "--no-viewer", "--out", str(tmp_path)])
    assert code in (0, 3)
    out = capsys.readouterr().out
    assert "stage 0 (rows=3, cols=3): dt 0.0166667 s, 12 steps, 9 particles" in out
    assert "stage 1: dt 0.0166667 s, 12 steps, 25 particles" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [s["particles"] for s in summary["stages"]] == [9, 25]
    assert (tmp_path / "start_and_result.png").stat().st_size > 0  # a cloth's: side by side


def test_cli_refuses_coarse_meshes_with_rounds(capsys):
    from casadi_keyframe.cli import main

    assert main(["solve", "cloth_shapes", "--set", "rows=4", "--resolution", "rows=3,cols=3",
                 "--rounds", "2"]) == 2
    assert "do not combine" in capsys.readouterr().err
    assert main(["solve", "cloth_shapes", "--set", "rows=4", "--resolution", "rowz=3"]) == 2
    assert "rowz" in capsys.readouterr().err


def test_carried_controls_stay_within_the_targets_bounds():
    coarse, fine = toss(3), toss(5)  # the centre particle is on both meshes
    top = fine.bounds()[1][0]
    spike = np.zeros((9, 3))
    spike[4, 2] = top  # at the bound: the momentum correction would lift it past
    moved = carry_to_mesh(coarse, spike.ravel(), fine).reshape(25, 3)
    assert moved[12, 2] == top and np.all(moved <= top)
