"""Argument checks: finite and positive numbers and fields, times on the step grid."""
from dataclasses import dataclass

import numpy as np
import pytest

from casadi_keyframe.checks import check_fields, check_number, frame_at


def test_numbers_come_back_as_floats_and_bad_ones_are_named():
    assert check_number("x", 3) == 3.0 and isinstance(check_number("x", 3), float)
    np.testing.assert_array_equal(check_number("x", (1, 2), positive=True), [1.0, 2.0])
    with pytest.raises(ValueError, match="x must be finite, got nan"):
        check_number("x", np.nan)
    with pytest.raises(ValueError, match="x must be positive and finite"):
        check_number("x", (1.0, 0.0), positive=True)


def test_fields_are_named_by_their_type():
    @dataclass
    class Clip:
        speed: float = 1.0
        period: float = 0.0

    check_fields(Clip(), finite=("speed", "period"))
    with pytest.raises(ValueError, match="Clip.period must be positive"):
        check_fields(Clip(), finite=("speed",), positive=("period",))


def test_a_time_on_the_grid_gives_its_frame_and_one_off_it_is_refused():
    assert frame_at(0.8, 1 / 60, "t") == 48 and frame_at(1 / 3, 1 / 60, "t") == 20
    with pytest.raises(ValueError, match="t = 0.805 s is not a whole number of steps"):
        frame_at(0.805, 1 / 60, "t")
    with pytest.raises(ValueError, match="t must be a finite time"):
        frame_at(np.inf, 1 / 60, "t")
