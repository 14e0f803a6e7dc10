"""MeshKeyframe: a target mesh's value, its gradient against CasADi reverse mode (plain and
weighted) and against central differences (aligned, where CasADi has no expression), the
topology checks and the misses."""
import numpy as np
import pytest

from casadi_keyframe.objectives import MeshKeyframe
from casadi_keyframe.meshes import check_mesh
from casadi_keyframe.models import ClothModel
from casadi_keyframe.objectives import Smoothness
from casadi_keyframe.scenes.cloths import cloth_problem, rotate_about
from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, wave
from casadi_keyframe.state import Trajectory

ROWS = COLS = 4


def sheet():
    vertices, quads = hanging_sheet(ROWS, COLS, 0.5)
    return vertices, quads, ClothModel.from_file(check_mesh(vertices, quads), pinned=[0, COLS - 1])


def problem(term, steps=6):
    _, _, model = sheet()
    return cloth_problem(model=model, steps=steps, dt=1 / 60, objective=term + Smoothness(1e-4),
                         name="mesh_term")


def random_controls(prob, seed=0):
    return 0.3 * np.random.default_rng(seed).standard_normal(prob.size)


def test_value_and_miss_against_numpy():
    v, quads, model = sheet()
    target = wave(v, 0.2)
    w = np.linspace(0, 2, len(v))
    term = MeshKeyframe(6, check_mesh(target, quads), weight=3.0, vertex_weights=w)
    prob = problem(term)
    traj = prob.simulate(random_controls(prob))
    bound = prob.objective_terms.state_terms[0]
    x = traj.x[6]
    assert bound.value(traj) == pytest.approx(
        0.5 * 3.0 * np.sum(w[:, None] * (x - target) ** 2), rel=1e-12)
    err = np.linalg.norm(x - target, axis=1)[1:]  # vertex 0 has weight 0: not counted
    miss = bound.miss(traj)
    assert miss["particles"] == len(v) - 1
    assert miss["rms_position_error"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)
    assert miss["max_position_error"] == pytest.approx(err.max(), rel=1e-12)


@pytest.mark.parametrize("weights", [False, True])
def test_gradient_matches_casadi_reverse_mode(weights):
    v, quads, _ = sheet()
    w = np.random.default_rng(1).uniform(0, 2, len(v)) if weights else None
    prob = problem(MeshKeyframe(5, check_mesh(fold(v, at=0.2, radius=0.1), quads), weight=50.0,
                                vertex_weights=w))
    u = random_controls(prob)
    f_adj, g_adj = prob.objective_and_gradient(u, "adjoint")
    f_ca, g_ca = prob.objective_and_gradient(u, "casadi")
    assert f_adj == pytest.approx(f_ca, rel=1e-10)
    assert np.linalg.norm(g_adj - g_ca) <= 1e-8 * np.linalg.norm(g_ca)


def test_aligned_value_ignores_where_the_target_is_and_how_it_is_turned():
    v, quads, _ = sheet()
    target = wave(v, 0.2)
    moved = rotate_about(target, (0.3, 1.0, -2.0), (1.0, 2.0, 0.5), 0.7) + [3.0, -1.0, 2.0]
    plain = problem(MeshKeyframe(6, check_mesh(target, quads), weight=7.0, align=True))
    turned = problem(MeshKeyframe(6, check_mesh(moved, quads), weight=7.0, align=True))
    traj = plain.simulate(random_controls(plain))
    a, b = (p.objective_terms.state_terms[0] for p in (plain, turned))
    assert a.value(traj) == pytest.approx(b.value(traj), rel=1e-9)
    assert a.miss(traj)["rms_position_error"] == pytest.approx(
        b.miss(traj)["rms_position_error"], rel=1e-9)
    # the shape itself, moved, is a perfect hit
    hit = Trajectory(np.repeat(moved[None], 7, 0), np.zeros((7, len(v), 3)), 1 / 60)
    assert a.value(hit) < 1e-20 and a.miss(hit)["rms_position_error"] < 1e-10


def test_aligned_gradient_matches_central_differences():
    v, quads, _ = sheet()
    w = np.random.default_rng(2).uniform(0.5, 2, len(v))
    prob = problem(MeshKeyframe(6, check_mesh(wave(v, 0.2), quads), weight=20.0,
                                vertex_weights=w, align=True))
    term = prob.objective_terms.state_terms[0]
    traj = prob.simulate(random_controls(prob))
    gx, gv = np.zeros_like(traj.x), np.zeros_like(traj.v)
    value = term.accumulate(traj, gx, gv)
    assert value == pytest.approx(term.value(traj), rel=1e-12)
    rng, h = np.random.default_rng(3), 1e-6
    for _ in range(3):  # in the state: the envelope theorem's gradient
        d = rng.standard_normal(traj.x[6].shape)
        shifted = [Trajectory(traj.x.copy(), traj.v, traj.dt) for _ in range(2)]
        shifted[0].x[6] += h * d
        shifted[1].x[6] -= h * d
        slope = (term.value(shifted[0]) - term.value(shifted[1])) / (2 * h)
        assert np.sum(gx[6] * d) == pytest.approx(slope, rel=1e-6)
    u = random_controls(prob)  # and through the whole simulation, in the controls
    _, g = prob.objective_and_gradient(u, "adjoint")
    for _ in range(2):
        d = rng.standard_normal(prob.size)
        slope = (prob.objective(u + h * d) - prob.objective(u - h * d)) / (2 * h)
        assert g @ d == pytest.approx(slope, rel=1e-5)


def test_aligned_target_is_refused_by_the_casadi_route_and_hard_keyframes():
    v, quads, _ = sheet()
    prob = problem(MeshKeyframe(6, check_mesh(v, quads), align=True))
    with pytest.raises(ValueError, match="align=True has no CasADi expression"):
        prob.objective_and_gradient(np.zeros(prob.size), "casadi")
    with pytest.raises(ValueError, match="aligned target cannot be moved"):
        prob.objective_terms.state_terms[0].aiming(0.1)


def test_another_mesh_is_refused_with_what_differs(tmp_path):
    v, quads, _ = sheet()
    small_v, small_q = hanging_sheet(ROWS, COLS - 1)
    with pytest.raises(ValueError, match="has 12 vertices, the cloth 16"):
        problem(MeshKeyframe(6, check_mesh(small_v, small_q)))
    flipped = quads[:, [1, 2, 3, 0]]  # the other diagonal of every quad
    with pytest.raises(ValueError, match="the cloth's 16 vertices but other faces"):
        problem(MeshKeyframe(6, check_mesh(v, flipped)))
    with pytest.raises(ValueError, match="outside 0..6"):
        problem(MeshKeyframe(9, check_mesh(v, quads)))
