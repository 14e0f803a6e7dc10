"""The scenes' rotations: one helper for coordinate axes and any axis, and the geodesic."""
import numpy as np
import pytest

from casadi_keyframe.scenes.maths import rotation, slerp


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_coordinate_axis_turns_as_that_unit_vector_does(axis):
    unit = np.eye(3)[axis]
    np.testing.assert_allclose(rotation(axis, 0.7), rotation(unit, 0.7), atol=1e-15)
    np.testing.assert_allclose(rotation(axis, 0.7) @ unit, unit, atol=1e-15)
    assert rotation(2, np.pi / 2) @ [1, 0, 0] == pytest.approx([0, 1, 0], abs=1e-15)


def test_slerp_runs_along_the_shortest_turn():
    start, end = rotation((1, 2, 3), 0.4), rotation((1, 2, 3), 1.0)
    np.testing.assert_allclose(slerp(start, end, 0.0), start, atol=1e-14)
    np.testing.assert_allclose(slerp(start, end, 1.0), end, atol=1e-14)
    np.testing.assert_allclose(slerp(start, end, 0.5), rotation((1, 2, 3), 0.7), atol=1e-14)


def test_a_bad_coordinate_axis_is_refused():
    with pytest.raises(ValueError, match="0, 1 or 2"):
        rotation(3, 0.1)


def test_turn_angle_is_the_best_fitting_rotation():
    from casadi_keyframe.scenes.maths import turn_angle

    p = np.random.default_rng(0).standard_normal((30, 3))
    turned = p @ rotation((0.3, 1.0, 0.2), np.radians(160)).T + 5.0
    assert turn_angle(p, turned) == pytest.approx(160, abs=1e-9)
    noisy = turned + 0.01 * np.random.default_rng(1).standard_normal(turned.shape)
    assert turn_angle(p, noisy) == pytest.approx(160, abs=1.0)


def test_a_wave_across_keeps_every_rows_length():
    from casadi_keyframe.models import ClothModel
    from casadi_keyframe.scenes.cloths import wave_across

    rows, cols = 9, 11
    rest = ClothModel.grid(rows, cols).rest_positions  # plane xz, row 0 on top
    depth = rest[:, 2].max() - rest[:, 2]
    wave = wave_across(rest, 0.2 * depth, along=0, out=1).reshape(rows, cols, 3)
    grid = rest.reshape(rows, cols, 3)
    np.testing.assert_allclose(wave[0], grid[0])  # no wave, no change
    np.testing.assert_allclose(wave[..., 2], grid[..., 2])  # rows stay at their height
    bottom = wave[-1]
    assert 0.3 < np.ptp(bottom[:, 1]) <= 2 * 0.2 + 1e-12  # a full period (crests between)
    chords = np.linalg.norm(np.diff(bottom, axis=0), axis=1)
    spacing = 1.0 / (cols - 1)
    assert np.all(chords <= spacing + 1e-12) and chords.sum() > 0.95  # chords of arcs 0.1 long
    assert np.ptp(bottom[:, 0]) < 0.9  # so it spans less
    assert np.mean(bottom[:, 0]) == pytest.approx(0.5)  # about the middle
