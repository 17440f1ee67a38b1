"""COCO metrics and apex matching against hand-computed cases."""

import numpy as np
import pytest

from gpr3d.detection.evaluate import apex_matches, coco_metrics


def test_perfect_and_shifted_boxes():
    gt = [np.array([[10.0, 10, 60, 40], [100, 50, 160, 90]])]
    m = coco_metrics(gt, [gt[0].copy()], [np.array([0.9, 0.8])])
    assert m["mAP@0.5"] == pytest.approx(1.0) and m["mAP@0.75"] == pytest.approx(1.0)
    assert m["AR@100"] == pytest.approx(1.0)
    # shift every box right by 12.5 px of 50 or 60: IoU 37.5/62.5 = 0.6 and 47.5/72.5 = 0.655
    shifted = gt[0] + np.array([12.5, 0, 12.5, 0])
    m = coco_metrics(gt, [shifted], [np.array([0.9, 0.8])])
    assert m["mAP@0.5"] == pytest.approx(1.0)
    assert m["mAP@0.75"] == pytest.approx(0.0)


def test_missed_target_halves_recall():
    gt = [np.array([[10.0, 10, 60, 40]]), np.array([[0.0, 0, 30, 30]])]
    m = coco_metrics(gt, [gt[0].copy(), np.zeros((0, 4))], [np.array([0.9]), np.zeros(0)])
    assert m["AR@100"] == pytest.approx(0.5)
    assert m["mAP@0.5"] == pytest.approx(0.5, abs=0.01)  # precision 1 up to recall 0.5, then nothing


def test_apex_matching_one_to_one():
    true = [[50, 10e-9], [100, 12e-9]]
    found = [[51, 10.1e-9], [52, 10.0e-9], [100, 13e-9]]  # two claim the first; the third is 1 ns late
    got = apex_matches(true, found, [0.9, 0.8, 0.7], max_traces=3, max_s=0.25e-9)
    assert got == (1, 2)
    found, false, hit = apex_matches(true, found, [0.9, 0.8, 0.7], max_traces=3, max_s=0.25e-9, return_found=True)
    assert (found, false) == (1, 2) and list(hit) == [True, False]
    assert apex_matches(true, [], [], max_traces=3, max_s=1e-9) == (0, 0)
