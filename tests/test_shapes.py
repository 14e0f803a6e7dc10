"""Shapes: exact signed distances, continuous across edges, and finite region gradients."""
from types import SimpleNamespace

import numpy as np
import pytest

from casadi_keyframe import RegionTarget
from casadi_keyframe.models import FlockModel
from casadi_keyframe.shapes import Box, Disc, Polygon, cross


def test_box_distance_is_exact_outside_and_inside():
    box = Box((0.3, -0.2), (2, 1))
    one_out = [[2.3, -0.2], [0.3, 1.3], [-1.7, 0.1], [0.0, -1.7]]
    assert np.max(np.abs(box.signed_distance(one_out) - 1.0)) <= 1e-15
    corner = box.signed_distance([[3.3, 1.8]])[0]  # 2 m right, 1.5 m above a corner
    assert corner == pytest.approx(2.5, rel=1e-15)
    inside = box.signed_distance([[0.5, -0.1], [0.3, -0.2]])
    np.testing.assert_allclose(inside, [-0.4, -0.5], rtol=0, atol=1e-15)


def test_disc_distance_is_exact():
    disc = Disc((1, 1), 1)
    np.testing.assert_array_equal(disc.signed_distance([[4, 5], [1, 1], [1.5, 1], [1, -1]]),
                                  [4.0, -1.0, -0.5, 1.0])


def test_polygon_distance_is_continuous_across_every_edge():
    poly = cross((0.2, -0.1), 4, 1)
    a = poly.vertices
    b = np.roll(a, -1, axis=0)
    e = b - a
    area2 = np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])  # > 0: counter-clockwise
    out = np.sign(area2) * np.c_[e[:, 1], -e[:, 0]] / np.linalg.norm(e, axis=1)[:, None]
    for s in (0.5, 0.3):  # two points along each edge, away from its corners
        on = a + s * e
        d_out = poly.signed_distance(on + 1e-9 * out)
        d_in = poly.signed_distance(on - 1e-9 * out)
        np.testing.assert_allclose(d_out, 1e-9, rtol=1e-3)
        np.testing.assert_allclose(d_in, -1e-9, rtol=1e-3)
        assert np.max(d_out - d_in) < 2.1e-9


SHAPES = [Box((0.3, -0.2), (2, 1)), Disc((1, 1), 0.7),
          Polygon([[0, 0], [2, 0], [2, 1], [1, 0.4], [0, 1]])]  # not convex


def _term(shape, points, margin):
    """A region term bound to a flock of ``len(points)`` agents: value and x-gradient."""
    term = RegionTarget(0, shape, weight=1.5, margin=margin)
    model = FlockModel(np.ones(len(points)))
    term = term.bind(model, 0)

    def value_and_grad(x):
        traj = SimpleNamespace(x=[x], v=[np.zeros_like(x)])
        gx, gv = [np.zeros_like(x)], [np.zeros_like(x)]
        return term.accumulate(traj, gx, gv), gx[0]
    return value_and_grad


@pytest.mark.parametrize("shape", SHAPES, ids=lambda s: type(s).__name__)
def test_region_gradient_matches_central_differences(shape):
    rng = np.random.default_rng(0)
    x = rng.uniform(-1.5, 3, (40, 2))  # inside, within the margin, and outside
    f = _term(shape, x, margin=0.3)
    _, g = f(x)
    h = 1e-6
    rng_d = np.random.default_rng(1)
    for _ in range(5):
        d = rng_d.standard_normal(x.shape)
        slope = (f(x + h * d)[0] - f(x - h * d)[0]) / (2 * h)
        assert np.sum(g * d) == pytest.approx(slope, rel=1e-7, abs=1e-9)


@pytest.mark.parametrize("shape, points", [
    (Disc((1, 1), 0.7), [[1, 1]]),  # the centre
    (Box((0.3, -0.2), (2, 1)), [[0.3, -0.2], [1.3, 0.3], [-0.7, -0.7]]),  # centre, corners
    (cross((0, 0), 4, 1), [[0, 0], [0.5, 0.5], [0.5, 1.0], [2, 0]]),  # centre, vertices, edge
], ids=["disc", "box", "cross"])
def test_region_gradient_is_finite_where_the_square_root_meets_zero(shape, points):
    x = np.asarray(points, dtype=float)
    for margin in (0.0, 5.0):  # inactive and active there
        _, g = _term(shape, x, margin)(x)
        assert np.all(np.isfinite(g))
