import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.migration.masking import box_mask, check_boxes

DT = 0.1e-9  # 200 samples: a 20 ns window


def test_box_mask_is_one_inside_and_tapers_to_zero():
    m = box_mask(50, 200, DT, [[10, 5e-9, 20, 8e-9]], taper_traces=3)
    assert m[15, 65] == 1.0 and m[10, 50] == 1.0 and m[20, 80] == 1.0
    assert 0 < m[8, 65] < 1 and m[5, 65] == 0 and m[30, 65] == 0
    assert 0 < m[15, 48] < 1 and m[15, 40] == 0
    assert np.all(np.diff(m[10:21, 65]) == 0)


@pytest.mark.parametrize("box, words", [
    ([1, 2e-9, 3], "must be 4 numbers"),
    ([1, "x", 3, 4e-9], "must be 4 numbers"),
    ([1, float("nan"), 3, 4e-9], "not finite"),
    ([5, 2e-9, 3, 4e-9], "empty"),
    ([1, 4e-9, 3, 2e-9], "empty"),
    ([1, 5.0, 3, 9.0], "in seconds"),  # nanoseconds given as seconds: far past the 20 ns window
    ([60, 1e-9, 70, 2e-9], "outside the data"),
])
def test_bad_boxes_get_a_one_line_error_naming_the_box(box, words):
    with pytest.raises(InvalidDataError, match=words) as e:
        check_boxes([[0, 0.0, 1, 1e-9], box], 50, 200 * DT)
    assert "box 1" in str(e.value) and "\n" not in str(e.value)
