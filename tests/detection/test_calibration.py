"""Platt scaling of detection scores (``gpr3d.detection.calibration``) against known maps and hand sums."""

import math

import numpy as np
import pytest

from gpr3d.core.errors import GPR3DError
from gpr3d.detection.calibration import box_truth, calibrate, check_calibration, fit_platt


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


@pytest.mark.parametrize("a0, b0", [(0.8, -1.5), (2.5, 0.7)])
def test_the_fit_recovers_the_map_that_made_the_truth(a0, b0):
    rng = np.random.default_rng(3)
    z = rng.uniform(-6, 6, 40_000)
    truth = rng.random(z.size) < _sigmoid(a0 * z + b0)  # drawn from the map itself
    a, b = fit_platt(_sigmoid(z), truth)
    # standard errors at this size are ~0.01 (a) and ~0.02 (b): 5 of them
    assert a == pytest.approx(a0, abs=0.06) and b == pytest.approx(b0, abs=0.1)


def test_a_perfectly_separated_set_still_gives_a_finite_increasing_map():
    scores, truth = [0.1, 0.2, 0.8, 0.9], [False, False, True, True]
    a, b = fit_platt(scores, truth)
    # the minimum of the logistic loss plus 1e-6 * n / 2 * (a^2 + b^2): its gradient, written out, is zero there
    z = np.log(np.array(scores) / (1 - np.array(scores)))
    p = _sigmoid(a * z + b)
    ridge = 1e-6 * len(scores)
    assert np.sum((p - truth) * z) + ridge * a == pytest.approx(0, abs=1e-9)
    assert np.sum(p - truth) + ridge * b == pytest.approx(0, abs=1e-9) and 5 < a < 20
    assert math.isfinite(a) and math.isfinite(b) and a > 0
    assert calibrate([0.2], {"method": "platt", "a": a, "b": b})[0] < 0.5 < calibrate([0.8], {"a": a, "b": b,
                                                                                             "method": "platt"})[0]


def test_calibrate_is_the_formula_by_hand_and_keeps_the_order():
    cal = {"method": "platt", "a": 2.0, "b": -1.0}
    # logit(0.9) = ln 9, so sigmoid(2 ln 9 - 1) = 81 / (81 + e) = 81 / 83.718282 = 0.967531
    assert calibrate([0.9], cal)[0] == pytest.approx(0.967531, abs=1e-6)
    # logit(0.25) = -ln 3, so sigmoid(-2 ln 3 - 1) = 1 / (1 + 9 e) = 1 / 25.464536 = 0.039270
    assert calibrate([0.25], cal)[0] == pytest.approx(0.039270, abs=1e-6)
    s = np.array([0.0, 0.05, 0.3, 0.5, 0.77, 0.999, 1.0])
    c = calibrate(s, cal)
    assert np.all(np.diff(c) > 0) and np.all((c > 0) & (c < 1))  # the ends clipped, not infinite
    assert np.array_equal(calibrate(s, None), s) and calibrate(s, None) is not s
    assert calibrate(s.astype(np.float32), None).dtype == np.float64  # the same type calibrated or not
    # float32 scores are mapped in float64: the logit of 0.9 in float32 is off by ~1e-7
    got = calibrate(np.array([0.9], np.float32), {"method": "platt", "a": 1.0, "b": 0.0})
    assert got.dtype == np.float64 and got[0] == pytest.approx(float(np.float32(0.9)), abs=1e-12)
    assert calibrate([], cal).shape == (0,)


@pytest.mark.parametrize("scores, truth, match", [
    ([0.2, 0.9], [True, True], "needs true and false boxes; got 2 true of 2"),
    ([0.2, 0.9], [False, False], "got 0 true of 2"),
    ([0.2, 0.9, 0.5], [True, False], "3 scores but 2 truth values"),
    ([0.2, float("nan")], [True, False], "^score calibration: the scores hold NaN or infinite values$"),
    ([0.1, 0.2, 0.8, 0.9], [True, True, False, False], "^score calibration: the fitted map does not increase with the "
     r"score \(a = -.*\): these scores do not rank true boxes above false ones$"),
])
def test_fit_refuses_what_it_cannot_fit(scores, truth, match):
    with pytest.raises(GPR3DError, match=match):
        fit_platt(scores, truth)


def test_the_fit_takes_scores_and_marks_of_any_shape_and_in_float64():
    rng = np.random.default_rng(5)
    s = rng.uniform(0.01, 0.99, 400)
    t = rng.random(400) < s
    flat = fit_platt(s, t)
    assert fit_platt(s.reshape(20, 20), t.reshape(400, 1)) == pytest.approx(flat, abs=1e-12)
    # float32 scores are read in float64 (their logits differ by ~1e-7 otherwise): the same map as their float64 copy
    s32 = s.astype(np.float32)
    assert fit_platt(s32, t) == pytest.approx(fit_platt(s32.astype(np.float64), t), abs=1e-12)
    assert fit_platt(s32, t.astype(np.float32)) == pytest.approx(fit_platt(s32.astype(np.float64), t), abs=1e-12)


def test_check_calibration_names_the_place_and_the_fault():
    good = {"method": "platt", "a": 0.9, "b": -2}
    assert check_calibration(None) is None and check_calibration(good) is good
    with pytest.raises(GPR3DError, match="^score calibration: expected"):
        check_calibration({"method": "platt!"})
    for bad, what in [({"method": "temperature", "a": 1, "b": 0}, "expected"), ("platt", "expected"),
                      ({"method": "platt", "a": -1, "b": 0}, "a must be a finite number > 0"),
                      ({"method": "platt", "a": 1, "b": float("inf")}, "a must be"),
                      ({"method": "platt", "a": True, "b": 0}, "a must be"),
                      ({"method": "platt", "a": 1}, "a must be")]:
        with pytest.raises(GPR3DError, match=f"^weights.pt: {what}"):
            check_calibration(bad, "weights.pt")


def test_box_truth_matches_one_to_one_best_score_first():
    true = [[0, 0, 10, 10], [20, 0, 30, 10]]
    found = [[0, 0, 10, 10],  # on the first, but scored below its twin
             [1, 0, 11, 10],  # IoU 9/11 = 0.82 with the first, the better score: it takes it
             [20, 0, 26, 10],  # IoU 0.6 with the second
             [50, 0, 60, 10],  # on nothing
             [22, 0, 32, 10]]  # IoU 8/12 = 0.67 with the second, already taken by a better score
    got = box_truth(found, [0.5, 0.9, 0.8, 0.99, 0.3], true)
    assert got.tolist() == [False, True, True, False, False] and got.dtype == bool
    # scores of any shape, boxes as arrays of any float type
    same = box_truth(np.array(found, np.float32), np.array([[0.5, 0.9, 0.8, 0.99, 0.3]]), np.array(true, np.int64))
    assert same.tolist() == got.tolist()
    assert box_truth(found, [0.5, 0.9, 0.8, 0.99, 0.3], true, iou=0.7).tolist() == [False, True, False, False,
                                                                                    False]
    assert box_truth([], [], true).shape == (0,) and box_truth(found[:1], [0.5], []).tolist() == [False]
