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
