"""Windows of a record, by hand: the settings' edges with whole messages, the seconds per row, where windows start
(overlap, the last one flush with the record's end, padding), each window's pixel map and rendered block."""

import re

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.detection.windows import WindowConfig, make_window, prepare, rows_interval, windows
from gpr3d.processing.image import network_view, record_scale, render_channels


@pytest.mark.parametrize("kw", [dict(traces=16), dict(traces=4096), dict(rows=32), dict(rows=2048),
                                dict(overlap=0.0), dict(overlap=0.9), dict(style="hot")])
def test_window_settings_at_their_edges_pass(kw):
    assert WindowConfig(**kw).to_dict() == {**WindowConfig().to_dict(), **kw}


@pytest.mark.parametrize("kw, words", [
    (dict(traces=15), "window traces must be an integer in 16..4096, got 15"),
    (dict(traces=4097), "window traces must be an integer in 16..4096, got 4097"),
    (dict(traces=64.0), "window traces must be an integer in 16..4096, got 64.0"),
    (dict(rows=31), "window rows must be an integer in 32..2048, got 31"),
    (dict(rows=2049), "window rows must be an integer in 32..2048, got 2049"),
    (dict(rows="256"), "window rows must be an integer in 32..2048, got '256'"),
    (dict(overlap=-0.01), "window overlap must lie in 0..0.9, got -0.01"),
    (dict(overlap=0.91), "window overlap must lie in 0..0.9, got 0.91"),
    (dict(style="Hot"), "window style must be 'channels' or 'hot', got 'Hot'"),
])
def test_window_settings_outside_are_named_in_full(kw, words):
    with pytest.raises(InvalidDataError, match="^" + re.escape(words) + "$"):
        WindowConfig(**kw)


def _survey(n, ns=200, dt=0.1e-9, seed=0):
    return Survey(data=np.random.default_rng(seed).standard_normal((n, ns)).astype(np.float32), dt_s=dt,
                  frequency_hz=1e9)


@pytest.mark.parametrize("n, traces, overlap, starts", [
    (100, 32, 0.5, [0, 16, 32, 48, 64, 68]),  # steps of 16; the last flush with the end
    (96, 32, 0.5, [0, 16, 32, 48, 64]),  # the steps reach the end exactly
    (100, 32, 0.0, [0, 32, 64, 68]),
    (100, 32, 0.9, list(range(0, 69, 3)) + [68]),  # round(3.2) = 3
    (20, 32, 0.5, [0]),  # shorter than a window: one, padded
])
def test_window_starts(n, traces, overlap, starts):
    s = _survey(n)
    cfg = WindowConfig(traces=traces, rows=64, overlap=overlap)
    wins = windows(s, cfg)
    assert [w.trace_start for w in wins] == starts
    assert [w.n_traces for w in wins] == [min(traces, n - a) for a in starts]


def test_a_window_s_pixels_and_block():
    s = _survey(50, ns=200)
    cfg = WindowConfig(traces=32, rows=64, style="hot")
    spr = rows_interval(s, cfg)
    assert spr == pytest.approx(199 * 0.1e-9 / 63, rel=1e-12, abs=0)
    proc = prepare(s, cfg)
    np.testing.assert_array_equal(proc, network_view(s, 64))
    bare = WindowConfig(traces=32, rows=64, dewow=False, background=False, equalise=False)
    np.testing.assert_array_equal(prepare(s, bare), network_view(s, 64, dewow=False, background=False,
                                                                  equalise=False))
    scale = record_scale(proc)
    wins = windows(s, cfg)
    last = wins[-1]
    assert (last.trace_start, last.n_traces) == (18, 32)
    # column c is trace start + c at its centre, row r time r x spr
    assert last.pixmap.point_to_px(18.0, 0.0) == pytest.approx((0.5, 0.5))
    assert last.pixmap.point_to_px(18.0 + 31, 63 * spr) == pytest.approx((31.5, 63.5))
    np.testing.assert_array_equal(last.image, render_channels(proc[18:50], "hot", scale=scale))
    # past the record's end: zero traces
    w = make_window(proc, 40, cfg, spr, scale)
    assert w.n_traces == 10 and w.image.shape == (3, 64, 32)
    np.testing.assert_array_equal(w.image, render_channels(np.r_[proc[40:], np.zeros((22, 64), np.float32)], "hot",
                                                           scale=scale))
    # windows take the data already prepared when given
    other = proc * 0 + 1.0
    np.testing.assert_array_equal(windows(s, cfg, processed=other)[0].image,
                                  render_channels(other[:32], "hot", scale=record_scale(other)))
    # no settings: the defaults (256 traces, 256 rows)
    assert windows(_survey(300, ns=300))[0].image.shape == (3, 256, 256)


def _win(start=10, n=32, real=None, rows=64, spr=0.1e-9):
    from gpr3d.detection.windows import Window
    from gpr3d.io.coco import PixelMap

    return Window(np.zeros((3, rows, n), np.float32), PixelMap(start - 0.5, 1.0, -0.5 * spr, spr), start,
                  n if real is None else real)


def test_window_targets_by_hand():
    from gpr3d.detection.windows import window_targets

    spr = 0.1e-9
    win = _win(start=10, n=32, real=28)  # traces 10..37 real, the rest padding; pixel x = trace - 10 + 0.5

    def lab(t0, t1, apex, ta=1e-9, tb=3e-9, **kw):
        return {"box": [t0, ta, t1, tb], "apex_trace": apex, "apex_time_s": 2e-9, **kw}

    got = window_targets([lab(14, 20, 17), lab(14, 20, 17, visible=False), lab(50, 60, 55)], win)
    np.testing.assert_allclose(got, [[4.5, 10.5, 10.5, 30.5]], atol=1e-5)  # one: visible, apex inside
    # every kind of left-out label before a kept one: each is skipped, the list goes on
    skipped = [lab(14, 20, 17, visible=False), lab(50, 60, 55), lab(5.5, 13.5, 10),
               lab(14, 20, 17, ta=1.0e-9, tb=1.05e-9), lab(14, 20, 17)]
    np.testing.assert_allclose(window_targets(skipped, win), [[4.5, 10.5, 10.5, 30.5]], atol=1e-5)
    # a box exactly one pixel wide stays
    assert window_targets([lab(14, 15, 14.5)], win).shape == (1, 4)
    assert got.dtype == np.float32
    # cut by the window's left edge (pixel 0 = trace 9.5): kept, clipped, when 60 % or more of it is inside
    np.testing.assert_allclose(window_targets([lab(5.5, 15.5, 10)], win), [[0.0, 10.5, 6.0, 30.5]], atol=1e-5)
    assert window_targets([lab(6.5, 14.5, 10)], win).shape == (1, 4)  # 5 of 8 inside: 62.5 %
    assert window_targets([lab(5.5, 13.5, 10)], win).shape == (0, 4)  # 4 of 8: 50 %
    # the apex must lie in the window's real traces (its pixel 0 .. n_traces, ends included)
    assert window_targets([lab(9.5, 14, 9.5)], win).shape == (1, 4)
    assert window_targets([lab(9.0, 14, 9.4)], win).shape == (0, 4)
    assert window_targets([lab(30, 37.5, 37.5)], win).shape == (1, 4)
    assert window_targets([lab(30, 37.6, 37.6)], win).shape == (0, 4)
    # less than a pixel tall or wide inside: left out
    assert window_targets([lab(14, 20, 17, ta=1.0e-9, tb=1.05e-9)], win).shape == (0, 4)
    np.testing.assert_allclose(window_targets([lab(14, 20, 17, ta=-1e-9, tb=1e-9)], win), [[4.5, 0.0, 10.5, 10.5]],
                               atol=1e-5)  # clipped at the top
    np.testing.assert_allclose(window_targets([lab(14, 20, 17, tb=9e-9)], win), [[4.5, 10.5, 10.5, 64.0]],
                               atol=1e-5)  # and at the bottom


def test_merge_by_hand():
    """Boxes back to traces and seconds; a box cut by a window's inner edge loses to the whole one of the next
    window (its rank halved); the record's own edges cut nothing; boxes are clipped to the record."""
    from gpr3d.detection.windows import merge

    spr, dt = 0.1e-9, 0.1e-9
    a, b = _win(start=0, n=32), _win(start=16, n=32)

    def duel(first, second):
        """The record box and score of the better-ranked of two boxes (win, box, score) that see one target."""
        parts = [(w, np.array([bx], float), np.array([sc])) for w, bx, sc in (first, second)]
        boxes, scores = merge(parts, n_traces=48, dt_s=dt, nms=lambda bx, r, iou: [int(np.argmax(r))])
        return boxes[0], float(scores[0])

    # the same hyperbola: cut at a's right edge (x1 = 30 >= 32 - 2) scored 0.9, whole in b scored 0.6
    box, score = duel((a, [20.0, 10, 30.0, 30], 0.9), (b, [4.0, 10, 17, 30], 0.6))
    np.testing.assert_allclose(box, [16 - 0.5 + 4, 0.95e-9, 16 - 0.5 + 17, 2.95e-9], rtol=1e-9)
    assert score == 0.6
    assert duel((b, [2.0, 10, 10, 30], 0.9), (a, [17.5, 10, 26, 30], 0.6))[1] == 0.6  # cut at b's left edge
    assert duel((b, [2.5, 10, 10, 30], 0.9), (a, [17.5, 10, 26, 30], 0.6))[1] == 0.9  # 2.5 px in: not cut
    # b ends at the record's last trace: its right edge is the record's, nothing is cut there
    assert duel((b, [20.0, 10, 31.5, 30], 0.9), (a, [20.0, 10, 26, 30], 0.6))[1] == 0.9
    # at the record's own left edge a box is not cut: its rank stays, and it wins
    box, score = duel((a, [1.0, 10, 8, 30], 0.9), (b, [4.0, 10, 17, 30], 0.6))
    assert score == 0.9
    np.testing.assert_allclose(box, [0.5, 0.95e-9, 7.5, 2.95e-9], rtol=1e-9)
    # clipped to the record: traces 0 .. n - 1
    boxes, _ = merge([(a, np.array([[-5.0, 10, 40, 30]]), np.array([0.5]))], n_traces=40, dt_s=dt,
                     nms=lambda bx, r, iou: [0])
    assert boxes[0, 0] == 0.0 and boxes[0, 2] == 39.0
    # nms sees time in samples and the ranks; with torchvision's, overlapping duplicates go
    seen = {}

    def spy(bx, r, iou):
        seen.update(bx=bx.copy(), r=r.copy(), iou=iou)
        return [0]

    merge([(a, np.array([[2.0, 10, 8, 30], [3.0, 10, 9, 30]]), np.array([0.8, 0.7]))], n_traces=48, dt_s=dt, iou=0.4,
          nms=spy)
    np.testing.assert_allclose(seen["bx"], [[1.5, 9.5, 7.5, 29.5], [2.5, 9.5, 8.5, 29.5]], rtol=1e-9)
    assert seen["r"].tolist() == [0.8, 0.7] and seen["iou"] == 0.4
    boxes, scores = merge([(a, np.array([[2.0, 10, 8, 30], [2.5, 10, 8.5, 30], [20, 40, 25, 50]]),
                            np.array([0.8, 0.7, 0.5]))], n_traces=48, dt_s=dt)
    assert scores.tolist() == [0.8, 0.5]
    empty = merge([(a, np.zeros((0, 4)), np.zeros(0))], n_traces=48, dt_s=dt)
    assert empty[0].shape == (0, 4) and empty[1].shape == (0,)


def test_apex_of_box_by_the_label_rule():
    """Boxes are symmetric about the apex and start BOX_PAD_PERIODS / f above it: an uncut box's apex is its centre;
    a box cut by the record's first (last) trace takes its full width from the record's width rate and its apex
    lies half of it in from the uncut side; cut on both sides or by the record's end, the data decide."""
    from gpr3d.detection.windows import apex_of_box
    from gpr3d.io.coco import BOX_PAD_PERIODS

    f, spr = 1e9, 0.1e-9
    proc = np.zeros((60, 100), np.float32)
    pad = BOX_PAD_PERIODS / f
    assert apex_of_box(proc, [10, 1e-9, 30, 4e-9], spr, frequency_hz=f) == (20.0, pytest.approx(1e-9 + pad, abs=0))
    rate = 4e9  # traces of width per second of height beyond the pads
    h = 5e-9 - 1e-9 - 2 * pad
    tr, t = apex_of_box(proc, [0, 1e-9, 25, 5e-9], spr, frequency_hz=f, width_per_s=rate)
    assert tr == pytest.approx(25 - 0.5 * rate * h, abs=1e-9) and t == pytest.approx(1e-9 + pad, rel=1e-12, abs=0)
    tr, _ = apex_of_box(proc, [40, 1e-9, 59, 5e-9], spr, frequency_hz=f, width_per_s=rate)
    assert tr == pytest.approx(40 + 0.5 * rate * h, abs=1e-9)
    tr, _ = apex_of_box(proc, [40, 1e-9, 59, 5e-9], spr, frequency_hz=f, width_per_s=rate, n_traces=80)
    assert tr == 49.5  # not cut in an 80-trace record: the centre
    # a very wide rate puts the apex beyond the record: it stays on the record's first trace
    tr, _ = apex_of_box(proc, [0, 1e-9, 25, 5e-9], spr, frequency_hz=f, width_per_s=1e12)
    assert tr == 0.0


def test_apex_time_from_the_envelope_without_a_frequency():
    """No frequency: the apex time is the envelope's peak on the apex trace, in the box's upper half, refined by
    the parabola through its neighbours (a smooth Gaussian pulse here, centred between rows)."""
    from scipy.signal import hilbert

    from gpr3d.detection.windows import apex_of_box

    spr = 0.1e-9
    r = np.arange(100)
    pulse = np.exp(-0.5 * ((r - 30.3) / 3.0) ** 2) * np.cos(2 * np.pi * (r - 30.3) / 6.0)
    proc = np.tile(pulse, (40, 1)).astype(np.float32)
    tr, t = apex_of_box(proc, [10, 2e-9, 20, 8e-9], spr)
    env = np.abs(hilbert(proc[10:21].astype(np.float64), axis=1))[:, 20:81]
    col = env[5, :31]
    j = int(np.argmax(col))
    y = j + 0.5 * (col[j - 1] - col[j + 1]) / (col[j - 1] - 2 * col[j] + col[j + 1])
    assert tr == 15.0 and t == pytest.approx((20 + y) * spr, rel=1e-9, abs=0)
    assert abs(t - 30.3 * spr) < 0.3 * spr  # near the pulse's true centre
    # a box wholly outside the record's rows: no envelope, the box's top
    assert apex_of_box(proc, [10, 20e-9, 20, 30e-9], spr) == (15.0, 20e-9)


@pytest.mark.parametrize("box, want", [
    ([0.5, 1e-9, 25, 5e-9], "left"),  # within half a trace of the first trace: cut
    ([1.0, 1e-9, 25, 5e-9], 13.0),  # a trace in: whole, its centre
    ([40, 1e-9, 58.5, 5e-9], "right"),  # within 1.5 traces of the last (59): cut
    ([40, 1e-9, 58.0, 5e-9], 49.0),
    ([56, 1e-9, 59, 5e-9], 59.0),  # the full width would reach past the last trace: the last trace
])
def test_apex_of_a_box_at_the_record_s_sides(box, want):
    from gpr3d.detection.windows import apex_of_box
    from gpr3d.io.coco import BOX_PAD_PERIODS

    f, spr, rate = 1e9, 0.1e-9, 4e9
    pad = BOX_PAD_PERIODS / f
    half = 0.5 * rate * (box[3] - box[1] - 2 * pad)  # 5.2 traces
    tr, t = apex_of_box(np.zeros((60, 100), np.float32), box, spr, frequency_hz=f, width_per_s=rate)
    want = {"left": box[2] - half, "right": box[0] + half}.get(want, want)
    assert tr == pytest.approx(want, abs=1e-9) and t == pytest.approx(box[1] + pad, rel=1e-12, abs=0)


def test_a_box_reaching_the_record_s_end_takes_its_apex_from_the_data():
    """A cut box whose bottom reaches 99 % of the record's last row (9.801 ns of 9.9) gets no full width from the
    rate (the end may have cut it too): with no data in it, its centre."""
    from gpr3d.detection.windows import apex_of_box
    from gpr3d.io.coco import BOX_PAD_PERIODS

    f, spr, rate = 1e9, 0.1e-9, 4e9
    proc = np.zeros((60, 100), np.float32)
    end = 0.99 * (100 - 1) * spr
    assert apex_of_box(proc, [0, 1e-9, 25, end], spr, frequency_hz=f, width_per_s=rate)[0] == 12.5
    below = 0.99 * 98.5 * spr  # just above: the rate decides
    tr, _ = apex_of_box(proc, [0, 1e-9, 25, below], spr, frequency_hz=f, width_per_s=rate)
    assert tr == pytest.approx(25 - 0.5 * rate * (below - 1e-9 - 2 * BOX_PAD_PERIODS / f), abs=1e-9)


@pytest.mark.parametrize("centre, want", [(19.7, 20.0), (21.4, None), (48.4, None), (49.4, 49.0)])
def test_apex_time_at_the_ends_of_the_envelope_s_search(centre, want):
    """The envelope's peak is searched in the upper half of the box (rows 20 .. 49 here) and refined by a parabola
    only between two neighbours: a peak on the first or last searched row stays on it; one a row in is refined."""
    from gpr3d.detection.windows import apex_of_box

    spr = 0.1e-9
    r = np.arange(140)
    pulse = np.exp(-0.5 * ((r - centre) / 3.0) ** 2) * np.cos(2 * np.pi * (r - centre) / 6.0)
    tr, t = apex_of_box(np.tile(pulse, (40, 1)).astype(np.float32), [10, 2.05e-9, 20, 7.85e-9], spr)
    assert tr == 15.0
    if want is not None:
        assert t == pytest.approx(want * spr, rel=1e-12, abs=0)
    else:
        assert abs(t / spr - centre) < 0.1  # the peak row itself is 0.4 rows off


def test_a_cut_box_without_a_rate_takes_the_middle_of_its_earliest_arrivals():
    """Arrivals on row 30 for traces 1 .. 9 and 3 rows later each trace beyond: smoothed over five traces, traces
    3 .. 7 lie within half a row of the earliest, and the apex is their middle one, 5."""
    from gpr3d.detection.windows import apex_of_box
    from gpr3d.io.coco import BOX_PAD_PERIODS

    spr, f = 0.1e-9, 1e9
    proc = np.zeros((60, 120), np.float32)
    for i in range(21):
        row = 30 + 3 * max(abs(i - 5) - 4, 0)
        proc[i, row - 2: row + 3] = [0.5, 1.0, 0.0, -1.0, -0.5]
    tr, t = apex_of_box(proc, [0, 2.5e-9, 20, 11.5e-9], spr, frequency_hz=f)
    assert tr == 5.0 and t == pytest.approx(2.5e-9 + BOX_PAD_PERIODS / f, rel=1e-12, abs=0)


def test_fuse_views_by_hand():
    from gpr3d.detection.windows import fuse_views

    dt = 1e-10  # time compared in samples: 1 ns is 10 samples
    boxes = np.array([[10.0, 1e-9, 20.0, 3e-9],  # A, score 0.9
                      [11.0, 1e-9, 21.0, 3e-9],  # A's twin (IoU 9/11)
                      [15.0, 1e-9, 25.0, 3e-9],  # IoU 5/15 with A, 6/14 with the twin: a group of its own
                      [10.0, 1.8e-9, 20.0, 3e-9],  # inside A, IoU 0.6: joins A
                      [40.0, 5e-9, 44.0, 6e-9]])  # alone
    scores = np.array([0.9, 0.6, 0.8, 0.3, 0.2])
    keep, fused = fuse_views(boxes, scores, dt)
    assert keep.tolist() == [0, 2, 4]
    a = (0.9 * boxes[0] + 0.6 * boxes[1] + 0.3 * boxes[3]) / 1.8
    assert np.allclose(fused, [a, boxes[2], boxes[4]], rtol=1e-12, atol=0)
    keep, best = fuse_views(boxes, scores, dt, average=False)
    assert keep.tolist() == [0, 2, 4] and np.array_equal(best, boxes[[0, 2, 4]])
    keep, fused, votes = fuse_views(boxes, scores, dt, n_views=2)
    assert votes == pytest.approx([0.9, 0.4, 0.1], rel=1e-12)  # (0.9 + 0.6 + 0.3) / 2, 0.8 / 2, 0.2 / 2
    assert fuse_views(boxes, scores, dt, n_views=1)[2] == pytest.approx([1.0, 0.8, 0.2], rel=1e-12)  # 1.8 capped
    # the IoU is taken with time in samples: the same boxes in seconds at another dt group alike
    assert fuse_views(boxes * [1, 10, 1, 10], scores, 10 * dt)[0].tolist() == [0, 2, 4]
    # nothing in, nothing out; a count mismatch named
    k, b = fuse_views(np.zeros((0, 4)), np.zeros(0), dt)
    assert k.shape == (0,) and b.shape == (0, 4)
    with pytest.raises(InvalidDataError, match="^5 boxes but 4 scores$"):
        fuse_views(boxes, scores[:4], dt)
    with pytest.raises(InvalidDataError, match=r"^the sample interval must be a positive number of seconds, got 0\.0$"):
        fuse_views(boxes, scores, 0.0)


def test_soften_duplicates_by_hand():
    from gpr3d.detection.windows import DUPLICATE_IOU, soften_duplicates

    assert DUPLICATE_IOU == 0.5  # the merge's own overlap
    dt = 1e-10
    boxes = np.array([[10.0, 1e-9, 20.0, 3e-9],  # A, score 0.9
                      [11.0, 1e-9, 21.0, 3e-9],  # B: IoU 9/11 with A
                      [40.0, 5e-9, 44.0, 6e-9],  # C: alone
                      [15.0, 1e-9, 25.0, 3e-9],  # D: IoU 5/15 with A, 6/14 with B: under the overlap
                      [12.0, 1e-9, 22.0, 3e-9]])  # E: IoU 8/12 with A, 9/11 with B, 7/13 with D: B's is the largest
    scores = np.array([0.9, 0.8, 0.7, 0.6, 0.5])
    got = soften_duplicates(boxes, scores, dt)
    want = [0.9, 0.8 * (1 - 9 / 11), 0.7, 0.6, 0.5 * (1 - 9 / 11)]
    assert got == pytest.approx(want, rel=1e-12, abs=0)
    assert scores.tolist() == [0.9, 0.8, 0.7, 0.6, 0.5]  # the caller's scores stay as they were
    # one pass, with the scores as given: E is compared with B at B's own 0.8, though B itself is lowered under E
    # the order is the scores', not the boxes': the same boxes listed backwards give the same scores backwards
    assert soften_duplicates(boxes[::-1], scores[::-1], dt) == pytest.approx(want[::-1], rel=1e-12, abs=0)
    # only a surer box lowers a score: with B the surer of the pair, A is lowered
    assert soften_duplicates(boxes[:2], [0.7, 0.8], dt) == pytest.approx([0.7 * (1 - 9 / 11), 0.8], rel=1e-12)
    # an overlap of exactly ``iou`` counts (A's left half has IoU 1/2 with A); one just under it does not
    half = np.array([[0.0, 0.0, 2.0, 1.0], [0.0, 0.0, 1.0, 1.0]])
    assert soften_duplicates(half, [0.9, 0.8], 1.0).tolist() == [0.9, 0.4]
    assert soften_duplicates(half, [0.9, 0.8], 1.0, iou=0.51).tolist() == [0.9, 0.8]
    assert soften_duplicates(half[:, [1, 0, 3, 2]], [0.9, 0.8], 1.0).tolist() == [0.9, 0.4]  # the halves in time
    # a tie keeps the boxes' order: of two equal boxes at one score the second falls to 0
    assert soften_duplicates(boxes[[0, 0]], [0.5, 0.5], dt).tolist() == [0.5, 0.0]
    # the IoU is taken with time in samples: the same boxes in seconds at another dt alike
    assert soften_duplicates(boxes * [1, 10, 1, 10], scores, 10 * dt) == pytest.approx(want, rel=1e-12, abs=0)
    # boxes side by side in traces or in time share nothing, however small; two one-sample boxes on one place all
    unit = [0.0, 0.0, 1.0, 1.0]
    assert soften_duplicates([unit, [2.0, 0.0, 3.0, 1.0]], [0.9, 0.8], 1.0).tolist() == [0.9, 0.8]
    assert soften_duplicates([unit, [0.0, 2.0, 1.0, 3.0]], [0.9, 0.8], 1.0).tolist() == [0.9, 0.8]
    assert soften_duplicates([unit, unit], [0.9, 0.8], 1.0).tolist() == [0.9, 0.0]
    assert soften_duplicates([unit, unit], [0.9, 0.8], 1.0, iou=1.0).tolist() == [0.9, 0.0]  # 1 is an overlap too
    tiny = [0.0, 0.0, 0.5, 0.5]  # (a quarter of a sample: the overlap is a share, whatever the boxes' size)
    assert soften_duplicates([tiny, tiny], [0.9, 0.8], 1.0).tolist() == [0.9, 0.0]
    # boxes without an area overlap nothing, even on one place
    flat = [5.0, 0.0, 5.0, 1.0]
    assert soften_duplicates([flat, flat], [0.9, 0.8], 1.0).tolist() == [0.9, 0.8]
    # whole numbers in, fractions out
    assert soften_duplicates([[10, 0, 20, 2], [11, 0, 21, 2]], [1, 1], 1.0) == pytest.approx([1.0, 2 / 11], rel=1e-12)
    # many boxes at two scores, each 0.01 traces right of the one before (IoU (10 - 0.01 d) / (10 + 0.01 d) at d apart):
    # the odd ones (0.6) come first in their own order, so each odd one after the first is lowered by its odd
    # neighbour two before it, and each even one (0.5) by an odd neighbour next to it (a sort that is not stable,
    # as numpy's default on 40 numbers, takes the odd ones in another order)
    many = np.array([[0.01 * k, 0.0, 10 + 0.01 * k, 1.0] for k in range(40)])
    got = soften_duplicates(many, np.where(np.arange(40) % 2 == 1, 0.6, 0.5), 1.0)
    want = [0.6 if k == 1 else 0.6 * 0.04 / 10.02 if k % 2 else 0.5 * 0.02 / 10.01 for k in range(40)]
    assert got == pytest.approx(want, rel=1e-9)
    assert soften_duplicates(np.zeros((0, 4)), np.zeros(0), dt).shape == (0,)
    with pytest.raises(InvalidDataError, match="^5 boxes but 4 scores$"):
        soften_duplicates(boxes, scores[:4], dt)
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(InvalidDataError, match=r"^the duplicates' overlap must lie in \(0, 1\], got "):
            soften_duplicates(boxes, scores, dt, iou=bad)
    for bad in (0.0, -dt, float("nan"), float("inf"), "1e-10", None, True):
        with pytest.raises(InvalidDataError, match="^the sample interval must be a positive number of seconds, got "):
            soften_duplicates(boxes, scores, bad)


def _half_width_by_brute_force(x):
    """The lag where the rows' summed autocorrelation (np.correlate, each row's mean removed) first falls to half."""
    x = x - x.mean(axis=0, keepdims=True)
    n = x.shape[0]
    ac = sum(np.correlate(x[:, r], x[:, r], mode="full")[n - 1:] for r in range(x.shape[1]))
    ac = ac / ac[0]
    k = int(np.nonzero(ac < 0.5)[0][0])
    return k - 1 + (ac[k - 1] - 0.5) / (ac[k - 1] - ac[k])


@pytest.mark.parametrize("sigma", [2.0, 7.5, 15.0])
def test_trace_width_is_the_half_width_of_the_autocorrelation(sigma):
    from gpr3d.detection.windows import trace_width

    rng = np.random.default_rng(1)
    i = np.arange(300)
    x = np.stack([np.exp(-(i - c) ** 2 / (2 * sigma**2)) * rng.choice([-1, 1]) for c in rng.uniform(40, 260, 48)], 1)
    w = trace_width(x.astype(np.float32))
    assert w == pytest.approx(_half_width_by_brute_force(x), rel=1e-5)
    # a Gaussian's autocorrelation is a Gaussian sqrt(2) wider: half at 2 sigma sqrt(ln 2) (the means removed
    # shorten it a little)
    assert 0.85 * 2 * sigma * np.sqrt(np.log(2)) < w <= 1.01 * 2 * sigma * np.sqrt(np.log(2))
    # the same features stretched twice as wide along the traces: twice the width
    wide = np.stack([np.exp(-(np.arange(600) - 2 * c) ** 2 / (2 * (2 * sigma) ** 2)) for c in rng.uniform(40, 260, 48)], 1)
    assert trace_width(wide) == pytest.approx(2 * trace_width(wide[::2]), rel=0.05)


def test_trace_width_of_records_without_a_decaying_width():
    from gpr3d.detection.windows import trace_width

    assert trace_width(np.ones((50, 8))) == 50.0  # nothing varies along the traces
    assert trace_width(np.zeros((50, 8))) == 50.0
    with pytest.raises(InvalidDataError, match=r"^a record of shape \(1, 8\) has no width along its traces$"):
        trace_width(np.ones((1, 8)))
