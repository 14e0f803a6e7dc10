"""Each cloth problem of the paper solves at a reduced size and reaches its keyframes."""
import numpy as np

from casadi_keyframe import load_problem, solve


def rms_misses(result):
    return [m["rms_position_error"] for m in result.breakdown["misses"]]


def test_cloth_arch_bends_into_the_arch():
    prob = load_problem("cloth_arch", rows=6, cols=6, steps=40)
    result = solve(prob, maxiter=120, quiet=True)
    start = prob.breakdown(prob.initial_controls())["misses"][0]["rms_position_error"]
    assert start > 0.15  # the flat sheet is far from the arch
    assert rms_misses(result)[0] < 0.03  # about 3% of the sheet's size


def test_cloth_shapes_swings_through_its_shapes():
    prob = load_problem("cloth_shapes", rows=6, cols=6, steps=60)
    result = solve(prob, maxiter=80, quiet=True)
    before = [m["rms_position_error"] for m in prob.breakdown(prob.initial_controls())["misses"]]
    after = rms_misses(result)
    assert max(before) > 0.3  # hanging still is far from the forward swing
    assert max(after) < 0.06 and all(a < b for a, b in zip(after, before)), (before, after)


def test_cloth_toss_flies_through_the_ring_and_turns_over():
    prob = load_problem("cloth_toss", rows=5, cols=5)
    result = solve(prob, maxiter=150, quiet=True)
    ring = prob.view.ring
    com, corners = result.breakdown["misses"][:2]
    assert com["position_error"] < 0.5 * ring.radius  # through the ring, near its centre
    assert corners["rms_position_error"] < 0.3  # upside down (a 1 m sheet turned over)
    frame = prob.objective_terms.state_terms[1].frame
    x = result.trajectory.x[frame]
    normal = np.cross(x[4] - x[0], x[20] - x[0])  # corners 0, cols-1, (rows-1) cols
    assert normal[2] < 0  # the sheet's upper face now points down
