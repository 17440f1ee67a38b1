"""benchmarks/pgpr_crossfit.py: wrong arguments are one line each, before any detection; the IoU a box is credited
follows the greedy, score-ordered matching of the COCO evaluation; the overlap features read the boxes above."""

import numpy as np
import pytest

from tests.tools._script import load_script, refusal


@pytest.mark.parametrize("args, line", [
    (["--powers", "9"], "--powers must lie in 0..8, got 9"),
    (["--seeds", "0"], "--seeds must lie in 1..20, got 0"),
    (["--threshold", "1"], "--threshold must lie in [0, 1), got 1"),
    (["--pgpr", "{tmp}"], "--pgpr {tmp}: no train/ folder in it (P-GPR's train/ and val/)"),
    (["--fold-refiners", "a", "b", "c", "d"],
     "--fold-refiners go with --folds (the detectors whose boxes they refine)"),
    (["--folds", "{tmp}/even.pt", "{tmp}/odd.pt"], "--folds: no such weights file: {tmp}/even.pt"),
])
def test_wrong_arguments_are_one_line(tmp_path, args, line):
    got = refusal("pgpr_crossfit.py", *(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert got == "pgpr_crossfit.py: error: " + line.replace("{tmp}", str(tmp_path))


LABELS = np.array([[0, 0, 10, 10], [20, 0, 30, 10], [40, 0, 50, 10]], float)
# IoU 0.6 and 0.8 with the first label, 0.4 with the second, exactly 0.5 with the third
BOXES = np.array([[0, 0, 10, 6], [0, 0, 10, 8], [20, 0, 30, 4], [40, 0, 50, 5]], float)


def test_each_label_is_credited_once_to_the_best_scored_box_at_iou_half_or_more():
    mod = load_script("benchmarks/pgpr_crossfit.py")
    got = mod.credited(BOXES, LABELS, np.array([0.9, 0.8, 0.7, 0.6]))
    np.testing.assert_allclose(got, [0.6, 0.0, 0.0, 0.5], atol=1e-12)
    # the better box scored first takes the label, the other one is a duplicate
    got = mod.credited(BOXES, LABELS, np.array([0.8, 0.9, 0.7, 0.6]))
    np.testing.assert_allclose(got, [0.0, 0.8, 0.0, 0.5], atol=1e-12)
    assert not mod.credited(BOXES, LABELS[:0], np.ones(4)).any()


def test_the_overlap_features_read_only_the_boxes_scored_above():
    mod = load_script("benchmarks/pgpr_crossfit.py")
    kinds = 2
    rec = {"bpx": BOXES, "scores": np.array([0.9, 0.8, 0.7, 0.6]), "dt": 1e-10, "n_samples": 20,
           "probs": np.full((4, kinds), 0.5), "q": np.array([0.1, 0.2, 0.3, 0.4])}
    x = mod.hand_features(rec)
    over, count = x[:, kinds + 5], x[:, kinds + 6]
    np.testing.assert_allclose(over, [0.0, 0.75, 0.0, 0.0], atol=1e-12)  # 60 shared of 80 with the 0.9 box
    np.testing.assert_array_equal(count, [0, 1, 0, 0])
    np.testing.assert_allclose(x[:, 0], np.log(rec["scores"] / (1 - rec["scores"])), rtol=1e-12)
    np.testing.assert_allclose(x[:, kinds + 1], np.log([10, 10, 10, 10]), rtol=1e-12)  # widths in traces
    np.testing.assert_allclose(x[:, kinds + 2], np.log([0.6, 0.8, 0.4, 0.5]), rtol=1e-12)  # heights in ns
    np.testing.assert_allclose(x[:, kinds + 8], [1.0, 0.8 / 0.9, 0.7 / 0.9, 0.6 / 0.9], rtol=1e-12)
    np.testing.assert_allclose(x[:, kinds + 9], rec["q"], rtol=1e-12)
    # a picture with no box describes none, in as many columns (the fit stacks every picture's rows)
    empty = dict(rec, bpx=BOXES[:0], scores=np.zeros(0), probs=np.zeros((0, kinds)), q=np.zeros(0))
    assert mod.hand_features(empty).shape == (0, x.shape[1])
    # without the refiner's quality: that column zero, every other the same
    y = mod.hand_features(rec, quality=False)
    np.testing.assert_array_equal(y[:, kinds + 9], 0.0)
    np.testing.assert_array_equal(np.delete(y, kinds + 9, axis=1), np.delete(x, kinds + 9, axis=1))


def test_rank_mapping_hands_the_pictures_own_scores_out_in_the_predictions_order():
    mod = load_script("benchmarks/pgpr_crossfit.py")
    scores = np.array([0.9, 0.7, 0.6, 0.2])
    got = mod.rank_mapped(scores, [0.1, 0.8, 0.5, 0.3])  # predicted best: box 1, then 2, 3, 0
    np.testing.assert_array_equal(got, [0.2, 0.9, 0.7, 0.6])
    assert sorted(got) == sorted(scores)  # the values a threshold sees are the picture's own
    np.testing.assert_array_equal(mod.rank_mapped(scores, [0.5, 0.5, 0.5, 0.5]), scores)  # ties: the order kept
    assert mod.rank_mapped(np.zeros(0), np.zeros(0)).shape == (0,)
