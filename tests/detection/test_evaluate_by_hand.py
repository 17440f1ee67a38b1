"""COCO metrics on a case worked out by hand (101-point interpolated AP, recall at 1 and 10 detections), the
apex matching's order and distance, and evaluate_detector's bookkeeping with a stand-in detector."""

import numpy as np
import pytest

from gpr3d.core.survey import Survey
from gpr3d.detection.evaluate import apex_matches, coco_metrics, evaluate_detector

pytest.importorskip("pycocotools")

S = 38 / 1.62  # a 100-wide box shifted by S overlaps its truth with IoU (100 - S) / (100 + S) = 0.62


def test_coco_metrics_by_hand():
    """Image 1: two truths found exactly (scores 0.9, 0.8) and a false box scored above them (0.95); image 2: one
    truth found at IoU 0.62 (0.7). In score order: FP, TP, TP, TP(IoU 0.62).
    IoU 0.5, 0.55, 0.6: precision 0, 1/2, 2/3, 3/4 at recall 0, 1/3, 2/3, 1: AP = 0.75 at every recall point.
    IoU 0.65 .. 0.95 (7 thresholds): the last is false: AP = 2/3 on the 67 recall points up to 0.66, else 0.
    AR@1 (the best-scored box per image): image 2's box only, found at 3 of the 10 thresholds: 1/3 x 3/10.
    AR@10: recall 1 at 3 thresholds and 2/3 at 7."""
    gt = [np.array([[10.0, 10, 60, 40], [100, 50, 160, 90]]), np.array([[0.0, 0, 100, 50]])]
    det = [np.array([[10.0, 10, 60, 40], [100, 50, 160, 90], [300, 300, 340, 330]]),
           np.array([[S, 0, 100 + S, 50]])]
    m = coco_metrics(gt, det, [np.array([0.9, 0.8, 0.95]), np.array([0.7])])
    ap_strict = 67 * (2 / 3) / 101
    assert m["mAP@0.5"] == pytest.approx(0.75, abs=1e-9)
    assert m["mAP@0.75"] == pytest.approx(ap_strict, abs=1e-9)
    assert m["mAP"] == pytest.approx((3 * 0.75 + 7 * ap_strict) / 10, abs=1e-9)
    assert m["AR@1"] == pytest.approx(0.1, abs=1e-9)
    assert m["AR@10"] == pytest.approx((3 + 7 * 2 / 3) / 10, abs=1e-9)
    assert m["AR@100"] == pytest.approx((3 + 7 * 2 / 3) / 10, abs=1e-9)
    assert m["recall@0.5"] == 1.0  # every truth matched at IoU 0.5, whatever the score
    assert set(m) == {"mAP", "mAP@0.5", "mAP@0.75", "AR@1", "AR@10", "AR@100", "recall@0.5"}
    none = coco_metrics(gt, [np.zeros((0, 4)), np.zeros((0, 4))], [np.zeros(0), np.zeros(0)])
    assert none == {"mAP@0.5": 0.0, "mAP@0.75": 0.0, "mAP": 0.0, "AR@1": 0.0, "AR@10": 0.0, "AR@100": 0.0,
                    "recall@0.5": 0.0}
    # recall@0.5 at IoU 0.62 but not past it: image 2's box shifted so that IoU is 0.45
    far = 55 / 1.45
    m = coco_metrics(gt, [det[0], np.array([[far, 0, 100 + far, 50]])], [np.array([0.9, 0.8, 0.95]), np.array([0.7])])
    assert m["recall@0.5"] == pytest.approx(2 / 3)


def test_class_averaged_metrics_count_a_box_only_under_its_kind():
    """Two images, a rebar and a pipe each, both found exactly; the pipe of image 2 is called a rebar and scored
    below the true rebar. Class-agnostic: every truth found first: AP 1. By kind: rebar AP 1 (its false box
    scores last), pipe: one of two found, ranked first: AP = 1 on the 51 recall points up to 0.5 -> 51/101;
    the mean over the two kinds; a third kind without truths does not count."""
    gt = [np.array([[0.0, 0, 50, 20], [100, 0, 150, 20]]), np.array([[0.0, 0, 50, 20], [100, 0, 150, 20]])]
    kinds_gt = [["rebar", "pvc_pipe"], ["rebar", "pvc_pipe"]]
    det = [g.copy() for g in gt]
    scores = [np.array([0.9, 0.8]), np.array([0.9, 0.3])]
    kinds_det = [["rebar", "pvc_pipe"], ["rebar", "rebar"]]
    agnostic = coco_metrics(gt, det, scores)
    assert agnostic["mAP@0.5"] == pytest.approx(1.0) and agnostic["recall@0.5"] == 1.0
    m = coco_metrics(gt, det, scores, gt_kinds=kinds_gt, det_kinds=kinds_det, kinds=["rebar", "pvc_pipe", "void"])
    assert m["mAP@0.5"] == pytest.approx((1.0 + 51 / 101) / 2, abs=1e-9)
    assert m["mAP"] == pytest.approx((1.0 + 51 / 101) / 2, abs=1e-9)  # exact boxes: the same at every IoU
    assert m["recall@0.5"] == pytest.approx((1.0 + 0.5) / 2)
    assert m["AR@100"] == pytest.approx((1.0 + 0.5) / 2)


def test_apex_matching_prefers_the_nearer_truth_in_both_units_and_goes_by_score():
    # B is nearer in time, A nearer in traces; measured in units of the limits, B is nearer: found 1 takes B
    true = [[10, 1.0e-9], [12, 1.1e-9]]
    found = [[10.9, 1.1e-9], [8, 1.0e-9]]  # the second can only reach A
    assert apex_matches(true, found, [0.9, 0.8], max_traces=3, max_s=0.25e-9) == (2, 0)
    # by score: the better-scored box takes its nearest (A), and the weaker one, which only A would take, is false
    true = [[10, 1.0e-9], [13, 1.0e-9]]
    found = [[11, 1.0e-9], [8, 1.0e-9]]
    got = apex_matches(true, found, [0.9, 0.1], max_traces=3, max_s=0.25e-9, return_found=True)
    assert got[:2] == (1, 1) and list(got[2]) == [True, False]
    # the limits themselves count: 3 traces and 0.5 s apart (exact in binary)
    assert apex_matches([[10, 1.0]], [[13, 1.5]], [0.5], max_traces=3, max_s=0.5) == (1, 0)
    assert apex_matches([[10, 1.0]], [[13.01, 1.5]], [0.5], max_traces=3, max_s=0.5) == (0, 1)


class _Stub:
    """A detector that answers each survey with the targets given for it (by its number of traces)."""

    def __init__(self, answers):
        self.answers = answers

    def detect(self, survey, score_threshold=0.0):
        return {"targets": self.answers[survey.n_traces], "n_windows": 2}


def test_evaluate_detector_bookkeeping():
    dt = 0.1e-9
    s1 = Survey(data=np.zeros((40, 100), np.float32), dt_s=dt, frequency_hz=1e9)
    s2 = Survey(data=np.zeros((30, 100), np.float32), dt_s=dt, frequency_hz=None,
                metadata={"scene": {"medium": {"kind": "soil"}}})

    def lab(box, apex, kind, visible=True):
        return {"box": box, "apex_trace": apex[0], "apex_time_s": apex[1], "kind": kind, "visible": visible}

    labels1 = {"labels": [lab([5, 1e-9, 15, 3e-9], (10, 1.5e-9), "rebar"),
                          lab([20, 2e-9, 30, 5e-9], (25, 2.5e-9), "pipe"),
                          lab([32, 1e-9, 38, 2e-9], (35, 1.2e-9), "rebar", visible=False)], "host": "concrete"}
    labels2 = {"labels": [lab([2, 4e-9, 12, 6e-9], (7, 4.4e-9), "rebar")]}

    def det(box, apex, score):
        return {"box": box, "apex_trace": apex[0], "apex_time_s": apex[1], "score": score}

    answers = {40: [det([5, 1e-9, 15, 3e-9], (10.5, 1.55e-9), 0.9),  # found (0.5 trace, 0.05 ns off)
                    det([20, 2e-9, 30, 5e-9], (25, 2.9e-9), 0.8),  # 0.4 ns late: more than a quarter period
                    det([0, 0, 3, 1e-9], (1, 0.5e-9), 0.3)],  # under the threshold: not counted
               30: [det([2, 4e-9, 12, 6e-9], (8, 4.6e-9), 0.6)]}  # 0.2 ns: within a quarter of 1 GHz's period
    logged = []
    m = evaluate_detector(_Stub(answers), [(s1, labels1), (s2, labels2)], score_threshold=0.5, log=logged.append)
    assert (m["n_records"], m["n_true"]) == (2, 3)
    assert m["apex_recall"] == pytest.approx(2 / 3) and m["false_per_true"] == pytest.approx(1 / 3)
    assert m["apex_recall_by_kind"] == {"pipe": {"found": 0, "n": 1, "recall": 0.0},
                                        "rebar": {"found": 2, "n": 2, "recall": 1.0}}
    assert m["rows"] == [
        {"record": 0, "n_true": 2, "n_detected": 2, "apex_found": 1, "false": 1, "n_traces": 40, "host": "concrete"},
        {"record": 1, "n_true": 1, "n_detected": 1, "apex_found": 1, "false": 0, "n_traces": 30, "host": "soil"}]
    assert m["score_threshold"] == 0.5 and 0 <= m["s_per_window"] < 1
    assert logged == ["  record 0: 2 true, 2 detected, 1 apexes found, 1 false",
                      "  record 1: 1 true, 1 detected, 1 apexes found, 0 false"]
    # the boxes in pixels: traces stay, seconds become samples; every detection counts for COCO, whatever its score
    px = np.array([1.0, 1 / dt, 1.0, 1 / dt])
    want = coco_metrics([np.array([[5, 1e-9, 15, 3e-9], [20, 2e-9, 30, 5e-9]]) * px,
                         np.array([[2, 4e-9, 12, 6e-9]]) * px],
                        [np.array([d["box"] for d in answers[40]]) * px, np.array([answers[30][0]["box"]]) * px],
                        [np.array([0.9, 0.8, 0.3]), np.array([0.6])])
    for k, v in want.items():
        assert m[k] == pytest.approx(v, abs=1e-12), k
    assert m["mAP@0.5"] == pytest.approx(1.0, abs=1e-12)  # every truth boxed exactly, above the one false box


def test_box_matches_one_to_one_by_score_at_the_iou_limit():
    from gpr3d.detection.evaluate import box_matches

    true = [[0.0, 0, 10, 10], [20, 0, 30, 10], [50, 0, 60, 10]]
    # found 1 (score 0.9) covers half of truth 0 (IoU 50 / 100 = 0.5, the limit: a match) and is matched first,
    # so found 0 (0.5), which fits truth 0 exactly, finds it taken; found 2 (0.7) meets truth 1 at IoU 1/3 (under
    # the limit); found 3 (0.8) is truth 2 exactly, of the wrong kind
    found = [[0.0, 0, 10, 10], [0, 0, 5, 10], [25, 0, 35, 10], [50, 0, 60, 10]]
    got = box_matches(true, ["rebar", "rebar", "void"], found, ["rebar", "void", "void", "rebar"], [0.5, 0.9, 0.7, 0.8])
    assert got[0] == (1, pytest.approx(0.5), False)  # the better-scored box wins truth 0, although found 0 fits it
    assert got[1] is None
    assert got[2] == (3, pytest.approx(1.0), False)
    assert box_matches(true, ["a"] * 3, [], [], []) == [None, None, None]
    assert box_matches([], [], found, ["a"] * 4, [1, 1, 1, 1]) == []
