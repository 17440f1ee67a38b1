"""The box refiner: edge moves and their inverse, the jitter's spread, the crops' geometry, that training
moves boxes onto a rule it can see, the ONNX export, and the detector applying it in record coordinates."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from gpr3d.core.errors import FormatError, InvalidDataError  # noqa: E402
from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.detection import refine as R  # noqa: E402


def _iou(a, b):
    ix = np.clip(np.minimum(a[:, 2], b[:, 2]) - np.maximum(a[:, 0], b[:, 0]), 0, None)
    iy = np.clip(np.minimum(a[:, 3], b[:, 3]) - np.maximum(a[:, 1], b[:, 1]), 0, None)
    inter = ix * iy
    return inter / ((a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1]) + (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1]) - inter)


def test_edge_moves_are_in_box_sizes_and_apply_deltas_undoes_them():
    boxes = np.array([[10.0, 20.0, 50.0, 40.0], [0.0, 0.0, 8.0, 4.0]])
    targets = np.array([[14.0, 18.0, 46.0, 50.0], [-2.0, 1.0, 12.0, 5.0]])
    d = R.box_deltas(boxes, targets)
    # first box: 40 wide, 20 high
    np.testing.assert_allclose(d[0], [4 / 40, -2 / 20, -4 / 40, 10 / 20])
    np.testing.assert_allclose(d[1], [-2 / 8, 1 / 4, 4 / 8, 1 / 4])
    np.testing.assert_allclose(R.apply_deltas(boxes, d), targets)


def test_a_box_thinner_than_two_pixels_counts_as_two_and_edges_never_cross():
    thin = np.array([[5.0, 5.0, 5.5, 9.0]])
    np.testing.assert_allclose(R.box_deltas(thin, [[6.0, 5.0, 5.5, 9.0]])[0, 0], 0.5)  # 1 px over 2, not 0.5
    crossed = R.apply_deltas([[10.0, 0.0, 20.0, 10.0]], [[0.8, 0.0, -0.8, 0.0]])  # left to 18, right to 12
    np.testing.assert_allclose(crossed, [[14.5, 0.0, 15.5, 10.0]])


def test_jitter_spreads_boxes_as_the_table_says():
    rng = np.random.default_rng(3)
    g = np.array([[100.0, 50.0, 140.0, 70.0]])  # 40 wide, 20 high
    j = R.jitter_boxes(g, 40000, rng)
    centre = 0.5 * (j[:, 0] + j[:, 2])
    assert abs(np.std((centre - 120.0) / 40.0) - R.JITTER["centre"]) < 0.003
    assert abs(np.mean((centre - 120.0) / 40.0)) < 0.002 and abs(np.mean((j[:, 1] - 50.0) / 20.0)) < 0.003
    assert abs(np.median(np.log((j[:, 2] - j[:, 0]) / 40.0))) < 0.005
    assert abs(np.std(np.log((j[:, 2] - j[:, 0]) / 40.0)) - R.JITTER["width"]) < 0.005
    assert abs(np.std((j[:, 1] - 50.0) / 20.0) - R.JITTER["top"]) < 0.003
    assert abs(np.median((j[:, 3] - 70.0) / 20.0)) < 0.01
    assert np.all(j[:, 3] > j[:, 1])
    assert abs(np.std((j[:, 3] - 70.0) / 20.0) - R.JITTER["bottom"]) < 0.005
    # a bottom drawn above the top is held 0.1 of the height and a pixel below it
    low = R.jitter_boxes(g, 4000, np.random.default_rng(5), spread={"top": 0.0, "bottom": 3.0})
    gap = low[:, 3] - low[:, 1]
    assert np.mean(gap <= 3.0 + 1e-9) > 0.2
    np.testing.assert_allclose(gap.min(), 0.1 * 20 + 1)
    j2 = R.jitter_boxes(g, 10, np.random.default_rng(3), spread={"width": 0.0})
    np.testing.assert_allclose(j2[:, 2] - j2[:, 0], 40.0)
    two = R.jitter_boxes([[0, 0, 10, 10], [100, 50, 140, 70]], 3, np.random.default_rng(4))  # label by label
    assert two.shape == (6, 4)
    assert np.all(np.abs(0.5 * (two[:3, 0] + two[:3, 2]) - 5) < 3) and np.all(np.abs(0.5 * (two[3:, 0] + two[3:, 2]) - 120) < 10)


def test_crops_sample_the_region_twice_the_box_about_its_centre():
    rows, cols = 60, 200
    image = np.zeros((3, rows, cols), np.float32)
    image[0] = np.arange(cols)[None, :]  # value = column index
    image[1] = np.arange(rows)[:, None]  # value = row index
    box = np.array([[80.0, 20.0, 112.0, 36.0]])  # 32 x 16, centre (96, 28)
    c = R.crops(image, box).numpy()
    assert c.shape == (1, 3, R.CROP, R.CROP)
    # pixel index k holds continuous coordinate k + 0.5 (aligned): bin i samples x0 + (i + 0.5) * bin
    x0, bx = 96.0 - R.EXPAND * 16.0, R.EXPAND * 32.0 / R.CROP
    y0, by = 28.0 - R.EXPAND * 8.0, R.EXPAND * 16.0 / R.CROP
    i = np.arange(R.CROP)
    np.testing.assert_allclose(c[0, 0, 10], x0 + (i + 0.5) * bx - 0.5, atol=1e-4)
    np.testing.assert_allclose(c[0, 1, :, 10], y0 + (i + 0.5) * by - 0.5, atol=1e-4)
    # a curved image: each bin is the mean of 2 x 2 bilinear samples (roi_align's sampling ratio 2), not of its
    # centre alone; pixel k holds f(k) = k^2, the samples lie at x0 + i * bx + (j + 0.5) * bx / 2, j = 0, 1
    image[2] = (np.arange(cols, dtype=np.float32) ** 2)[None, :]
    got = R.crops(image, box).numpy()[0, 2, 10]

    def lin(x):  # bilinear along x between pixel centres (at k + 0.5)
        u = x - 0.5
        k = np.floor(u)
        return k**2 * (1 - (u - k)) + (k + 1) ** 2 * (u - k)

    want = 0.5 * (lin(x0 + i * bx + 0.25 * bx) + lin(x0 + i * bx + 0.75 * bx))
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-3)
    # float64 pictures are cropped in float32, as the network computes
    c64 = R.crops(image.astype(np.float64), box)
    assert c64.dtype == torch.float32
    np.testing.assert_array_equal(c64.numpy(), R.crops(image, box).numpy())
    np.testing.assert_array_equal(R.crops(torch.from_numpy(image), box).numpy(), R.crops(image, box).numpy())
    held = torch.from_numpy(image).requires_grad_(True)  # a tensor in a graph (training's): its values
    np.testing.assert_array_equal(R.crops(held, box).numpy(), R.crops(image, box).numpy())


def test_crop_array_samples_as_torchvision_s_roi_align():
    """The crops are torchvision's ``roi_align`` (aligned, sampling ratio 2) of each box's region, computed
    without it: a random picture (every sampling setting shows), boxes inside, across every edge, wholly outside,
    thinner than the two-pixel floor, and a picture taller than wide."""
    from torchvision.ops import roi_align

    rng = np.random.default_rng(9)
    for rows, cols in ((50, 120), (300, 40)):
        image = rng.standard_normal((3, rows, cols)).astype(np.float32)
        x0, y0 = rng.uniform(-30, cols + 5, 40), rng.uniform(-20, rows + 5, 40)
        w, h = rng.uniform(0.2, 0.8 * cols, 40), rng.uniform(0.2, 0.8 * rows, 40)
        boxes = np.stack([x0, y0, x0 + w, y0 + h], axis=1).astype(np.float32)
        boxes[0] = [0.0, 0.0, cols, rows]  # the whole picture: its region overhangs every edge
        boxes[1] = [5.0, 5.0, 5.5, 6.0]  # thinner than two pixels both ways
        # 32 wide: a region of 64 bins of one pixel from -0.75, so its first sample lies at exactly -1 (still
        # sampled: the edge pixel); the next one's last sample at exactly the picture's width (also sampled)
        boxes[2] = [15.25, 0.0, 47.25, 10.0]
        boxes[3] = [cols - 31.25 - 16.0, 0.0, cols - 31.25 + 16.0, 10.0]
        boxes[4] = [0.0, 15.25, 10.0, 47.25]
        reg = torch.from_numpy(R._regions(boxes))
        want = roi_align(torch.from_numpy(image)[None], [reg], output_size=R.CROP, spatial_scale=1.0,
                         sampling_ratio=2, aligned=True).numpy()
        got = R.crop_array(image, boxes)
        assert got.shape == want.shape == (40, 3, R.CROP, R.CROP) and got.dtype == np.float32
        assert np.abs(want).max() > 1.0 and (want == 0).any()  # regions outside the picture are zero there
        # float32 both ways, summed in another order: apart by a few units of the last place of values up to ~4
        # (4.8e-7 measured); a sampling rule's mistake moves a bin by a share of a pixel's value (~0.1-1)
        np.testing.assert_allclose(got, want, atol=1e-5)
        # float64 boxes and pictures are cropped in float32, as the network computes: the float32 result exactly
        np.testing.assert_array_equal(R.crop_array(image.astype(np.float64), boxes.astype(np.float64)), got)
    assert R.crop_array(image, np.zeros((0, 4))).shape == (0, 3, R.CROP, R.CROP)


def test_the_mirrored_picture_s_crop_about_the_mirrored_box_is_the_crop_mirrored():
    """What lets both looks of the mirrored refinement share one crop: pixel ``c`` covers ``[c, c + 1)``, so the
    mirror takes ``x`` to ``cols - x``, and the crop it gives is the crop with its columns reversed."""
    rng = np.random.default_rng(4)
    image = rng.standard_normal((3, 70, 150)).astype(np.float32)
    boxes = np.array([[10.3, 5.0, 41.7, 30.2], [100.0, 20.0, 149.0, 69.0], [-3.0, 1.0, 20.0, 12.0],
                      [60.0, 30.0, 61.0, 31.0]], np.float32)
    mirrored = np.stack([150 - boxes[:, 2], boxes[:, 1], 150 - boxes[:, 0], boxes[:, 3]], axis=1)
    a = R.crop_array(image, boxes)
    b = R.crop_array(np.ascontiguousarray(image[..., ::-1]), mirrored)
    # the same to float32 rounding of the sample positions (a few 1e-6 px at 150 px, times a random picture's steps
    # between pixels, up to ~7: 5e-5 measured); the wrong orientation or a shifted region moves crops by ~1
    np.testing.assert_allclose(b, a[..., ::-1], atol=1e-3)
    assert np.abs(a - a[..., ::-1]).max() > 0.5  # the crops themselves are not symmetric


def _blob_records(n, rng, rows=64, cols=160):
    """Images with one bright bar each; its label box is the bar grown by a fixed rule (3 px sideways, 6 down)."""
    out = []
    for _ in range(n):
        img = rng.normal(0, 0.05, (3, rows, cols)).astype(np.float32)
        x0, y0 = rng.uniform(30, cols - 60), rng.uniform(8, rows - 30)
        w, h = rng.uniform(16, 30), rng.uniform(6, 12)
        img[:, int(y0) : int(y0 + h), int(x0) : int(x0 + w)] += 1.0
        label = np.array([[int(x0) - 3.0, int(y0), int(x0 + w) + 3.0, int(y0 + h) + 6.0]])
        out.append((img, label))
    return out


def test_training_moves_boxes_onto_a_rule_it_can_see():
    rng = np.random.default_rng(0)
    train = _blob_records(60, rng)
    net = R.train_refiner(train, epochs=6, per_label=16, batch=64)
    ref = R.BoxRefiner(net)
    before, after = [], []
    for img, label in _blob_records(20, np.random.default_rng(1)):
        start = R.jitter_boxes(label, 4, rng)
        moved = R.apply_deltas(start, ref.predict(img[None], start.astype(np.float32)))
        before.append(_iou(start, np.repeat(label, 4, 0)))
        after.append(_iou(moved, np.repeat(label, 4, 0)))
    before, after = np.concatenate(before), np.concatenate(after)
    assert after.mean() > before.mean() + 0.1, (before.mean(), after.mean())
    assert np.mean(after >= 0.75) > np.mean(before >= 0.75) + 0.2


def test_train_refiner_refuses_what_it_cannot_train_on(tmp_path):
    with pytest.raises(InvalidDataError, match="epochs"):
        R.train_refiner([], epochs=0)
    for kw in (dict(per_label=0), dict(batch=0)):
        with pytest.raises(InvalidDataError, match="must be positive"):
            R.train_refiner([], **kw)
    # the smallest settings are allowed, and a record without labels is passed over, not the end of the data
    img = np.random.default_rng(0).random((3, 32, 64), dtype=np.float32)
    one = np.array([[10.0, 8.0, 30.0, 20.0]])
    net = R.train_refiner([(img, np.zeros((0, 4))), (img, one)], epochs=1, per_label=1, batch=1)
    assert net[-1].out_features == 4 and not net.training
    with pytest.raises(InvalidDataError, match="^no labelled boxes to train the refiner on$"):
        R.train_refiner([(np.zeros((3, 32, 32), np.float32), np.zeros((0, 4)))], epochs=1)


def test_training_defaults_are_the_shipped_refiner_s_recipe():
    """``train_refiner``'s defaults are the recipe the shipped refiner records (9 epochs, 24 boxes a label, seed
    0) with batch 128 and peak rate 2e-3: a run with them spelled out gives the same weights."""
    import torch as _torch

    shipped = _torch.load(R.DEFAULT_REFINER, weights_only=False)["provenance"]
    assert (shipped["epochs"], shipped["per_label"], shipped["seed"]) == (9, 24, 0)
    rng = np.random.default_rng(1)
    img = rng.random((3, 40, 90), dtype=np.float32)
    boxes = np.array([[10.0, 8.0, 30.0, 20.0], [50.0, 5.0, 80.0, 30.0], [40.0, 20.0, 55.0, 36.0]])
    data = [(img, boxes), (img[:, ::-1].copy(), boxes + 2.0)]  # 144 crops: two batches of the default size
    a = R.train_refiner(data)
    b = R.train_refiner(data, epochs=9, per_label=24, batch=128, lr=2e-3, seed=0)
    c = R.train_refiner(data, epochs=9, per_label=24, batch=128, lr=2e-3, seed=1)
    # (the same run twice agrees to float32 rounding whatever the CPU's kernels; any other recipe moves the
    # weights by far more: its first step already draws other boxes)
    def gap(x, y):
        return max(float((vx.float() - vy.float()).abs().max()) for vx, vy in zip(x.state_dict().values(),
                                                                                 y.state_dict().values()))
    assert gap(a, b) < 1e-4
    assert gap(a, c) > 1e-2


def _survey(n_traces=300, n_samples=128, dt=5e-11):
    rng = np.random.default_rng(4)
    return Survey(data=rng.normal(size=(n_traces, n_samples)).astype(np.float32), dt_s=dt, frequency_hz=1.6e9)


def _coordinates(rows, cols):
    """A picture whose first channel holds each pixel's column centre (``c + 0.5``), its second the row centre:
    bilinear sampling of a linear picture is exact, so a crop of it tells its region (:func:`_box_of`)."""
    image = np.zeros((3, rows, cols), np.float32)
    image[0] = np.arange(cols)[None, :] + 0.5
    image[1] = np.arange(rows)[:, None] + 0.5
    return image


def _box_of(crop):
    """The box (pixels) a crop of :func:`_coordinates` was cut about: bin ``i`` of a region from ``lo`` with bins
    of ``step`` holds ``lo + (i + 0.5) * step``; the region is ``EXPAND`` times the box about its centre."""
    out = []
    for line in (crop[0, 0], crop[1, :, 0]):
        step = (line[-1] - line[0]) / (R.CROP - 1)
        lo = line[0] - 0.5 * step
        centre, half = lo + 0.5 * R.CROP * step, 0.5 * R.CROP * step / R.EXPAND
        out.append((centre - half, centre + half))
    (x0, x1), (y0, y1) = out
    return np.array([x0, y0, x1, y1])


class _Fixed:
    """A refiner whose network asks the same edge moves of every crop."""

    provenance = {"name": "fixed moves"}
    mirror, passes = False, 1  # one look at each box, as the moves it asks are written

    def __init__(self, d):
        self.d, self.seen = np.asarray(d, float), []

    def predict_crops(self, crops):
        self.seen.append(crops.copy())
        return np.repeat(self.d[None], len(crops), 0)

    rules, quality, rule, quality_weight, fine = (), False, "auto", R.QUALITY_WEIGHT, None  # one head, no quality
    refine, refine_scored, head_for = R.BoxRefiner.refine, R.BoxRefiner.refine_scored, R.BoxRefiner.head_for
    fine_for = R.BoxRefiner.fine_for
    weight_for = R.BoxRefiner.weight_for


def test_refine_works_in_the_record_image_pixels_and_returns_record_boxes():
    s = _survey()
    rows = 256
    spr = (s.n_samples - 1) * s.dt_s / (rows - 1)
    boxes = np.array([[70.0, 3e-9, 110.0, 4e-9]])
    fixed = _Fixed([0.1, -0.25, 0.0, 0.5])
    image = _coordinates(rows, s.n_traces)
    got = fixed.refine(s, rows, boxes, image)
    assert len(fixed.seen) == 1
    crops, = fixed.seen
    assert crops.shape == (1, 3, R.CROP, R.CROP) and crops.dtype == np.float32
    # trace i is pixel column i (its centre at i + 0.5), time t row t / spr (its centre at t / spr + 0.5)
    np.testing.assert_allclose(_box_of(crops[0]), [70.5, 3e-9 / spr + 0.5, 110.5, 4e-9 / spr + 0.5], rtol=1e-5)
    w, h = 40.0, 1e-9
    np.testing.assert_allclose(got[0], [70 + 0.1 * w, 3e-9 - 0.25 * h, 110.0, 4e-9 + 0.5 * h], rtol=1e-5)
    none = fixed.refine(s, rows, np.zeros((0, 4)), image)
    assert none.shape == (0, 4) and len(fixed.seen) == 1  # no boxes: the network is not asked


def _one_box_detector(cfg, boxes=((40.0, 30.0, 90.0, 60.0),), scores=(0.9,)):
    """A detector whose network finds the same boxes (one, score 0.9, unless told) in every window."""
    from gpr3d.detection.infer import Detector

    class Boxes(Detector):
        def predict_windows_kinds(self, images):
            k = len(scores)
            return [(np.array(boxes, float), np.array(scores, float), np.ones(k, np.int64), np.ones(k))
                    for _ in images]

    return Boxes(None, cfg)


def test_the_detector_refines_its_merged_boxes_before_it_reports_them():
    from gpr3d.detection.windows import WindowConfig

    s = _survey(n_traces=256)

    det = _one_box_detector(WindowConfig(traces=256, rows=128, overlap=0.0))
    plain = det.detect(s)
    assert plain["refiner"] is None
    plain, plain_refine = plain["targets"], plain["refine"]
    det.refiner = _Fixed([0.0, 0.0, 0.2, 0.1])
    found = det.detect(s)
    assert found["refiner"] == "fixed moves" and found["refine"] == {"mirror": False, "passes": 1, "fine": None,
                                                                            "duplicate_iou": 0.5}
    assert plain_refine is None
    det.refiner.mirror, det.refiner.passes = True, 3  # the JSON says how the refiner was applied
    assert det.detect(s)["refine"] == {"mirror": True, "passes": 3, "fine": None, "duplicate_iou": 0.5}
    det.refiner.mirror, det.refiner.passes = False, 1
    moved = found["targets"]
    assert len(plain) == len(moved) == 1  # one window
    a, b = np.asarray(plain[0]["box"]), np.asarray(moved[0]["box"])
    np.testing.assert_allclose(b[[0, 1]], a[[0, 1]])
    np.testing.assert_allclose(b[2] - a[2], 0.2 * (a[2] - a[0]), rtol=1e-6)
    np.testing.assert_allclose(b[3] - a[3], 0.1 * (a[3] - a[1]), rtol=1e-6)
    assert moved[0]["score"] == plain[0]["score"]


class _Onto(_Fixed):
    """A refiner that moves the second of the boxes it is given onto the first, five traces to the right."""

    provenance = {"name": "onto the first"}

    def refine_scored(self, survey, rows, boxes, image, *, score=True):
        out = np.array(boxes, float)
        out[1] = out[0] + [5.0, 0.0, 5.0, 0.0]
        return out, None


def test_a_box_the_refiner_moves_onto_a_surer_one_is_scored_lower():
    from gpr3d.detection.windows import WindowConfig

    s = _survey(n_traces=256)
    # two hyperbolas far apart (the merge keeps both), the second moved by the refiner onto the first
    det = _one_box_detector(WindowConfig(traces=256, rows=128, overlap=0.0),
                            boxes=((40.0, 30.0, 90.0, 60.0), (150.0, 30.0, 200.0, 60.0)), scores=(0.9, 0.8))
    plain = det.detect(s, score_threshold=0.1)["targets"]
    assert [t["score"] for t in plain] == pytest.approx([0.9, 0.8], rel=1e-6)
    det.refiner = _Onto([0.0] * 4)
    found = det.detect(s, score_threshold=0.1)["targets"]
    a, b = (np.asarray(t["box"]) for t in found)
    assert np.allclose(b - a, [5.0, 0.0, 5.0, 0.0], rtol=0, atol=1e-9)
    # the same height, 50 traces wide, 5 apart: IoU 45 / 55
    assert [t["score"] for t in found] == pytest.approx([0.9, 0.8 * (1 - 45 / 55)], rel=1e-6)
    # at the usual threshold the duplicate is not reported; the surer box stays as it was
    kept = det.detect(s)["targets"]
    assert len(kept) == 1 and kept[0]["box"] == found[0]["box"] and kept[0]["score"] == found[0]["score"]
    # another overlap (the JSON says which), or none: the refined boxes keep their scores
    det.duplicate_iou = 0.9
    got = det.detect(s, score_threshold=0.1)
    assert [t["score"] for t in got["targets"]] == pytest.approx([0.9, 0.8], rel=1e-6)
    assert got["refine"]["duplicate_iou"] == 0.9
    det.duplicate_iou = None
    got = det.detect(s, score_threshold=0.1)
    assert [t["score"] for t in got["targets"]] == pytest.approx([0.9, 0.8], rel=1e-6)
    assert got["refine"]["duplicate_iou"] is None


def test_the_refiner_sees_the_record_as_the_windows_render_it_and_is_timed():
    from gpr3d.core.timing import collect
    from gpr3d.detection.windows import WindowConfig, prepare

    s = _survey(n_traces=256)

    cfg = WindowConfig(traces=256, rows=128, overlap=0.0, style="hot")
    det = _one_box_detector(cfg)
    det.refiner = _Fixed([0.0, 0.0, 0.0, 0.0])
    det.refiner.provenance = {}  # a refiner without a name
    with collect(compile_times=False) as times:
        found = det.detect(s)
    assert found["refiner"] == "gpr3d box refiner"
    assert "refine" in times.seconds
    seen, = det.refiner.seen  # the window's box: record pixels [40, 30, 90, 60] (one window from trace 0)
    box = np.array([[40.0, 30.0, 90.0, 60.0]])
    np.testing.assert_array_equal(seen, R.crop_array(R.record_image(prepare(s, cfg), "hot"), box))
    assert not np.allclose(seen, R.crop_array(R.record_image(prepare(s, cfg), "channels"), box))


def test_only_the_boxes_reported_are_refined():
    """Each box is refined on its own, so the boxes under the score threshold (never reported) are not refined:
    the refiner sees the crops of the others only, and they move as when every box is refined."""
    from gpr3d.detection.windows import WindowConfig

    s = _survey(n_traces=256)
    cfg = WindowConfig(traces=256, rows=128, overlap=0.0)
    det = _one_box_detector(cfg, boxes=[[40.0, 30.0, 90.0, 60.0], [150.0, 20.0, 200.0, 70.0],
                                        [100.0, 60.0, 130.0, 90.0]], scores=[0.9, 0.3, 0.6])
    det.refiner = _Fixed([0.05, 0.0, 0.1, 0.2])
    det.refiner.mirror = True  # both looks of each box in one batch: crops, then the same crops mirrored
    high = det.detect(s, score_threshold=0.5)
    crops, = det.refiner.seen
    assert crops.shape == (4, 3, R.CROP, R.CROP)
    np.testing.assert_array_equal(crops[2:], crops[:2, ..., ::-1])
    det.refiner.seen = []
    every = det.detect(s, score_threshold=0.0)
    assert det.refiner.seen[0].shape == (6, 3, R.CROP, R.CROP)
    assert [t["score"] for t in high["targets"]] == [0.9, 0.6] and len(every["targets"]) == 3
    for t in high["targets"]:
        twin, = [u for u in every["targets"] if u["score"] == t["score"]]
        np.testing.assert_allclose(t["box"], twin["box"], rtol=1e-12)
    plain = _one_box_detector(cfg, boxes=[[40.0, 30.0, 90.0, 60.0], [150.0, 20.0, 200.0, 70.0],
                                          [100.0, 60.0, 130.0, 90.0]], scores=[0.9, 0.3, 0.6]).detect(s)
    det.refiner.seen = []
    edge = det.detect(s, score_threshold=0.6)  # a score equal to the threshold is reported, and refined
    assert [t["score"] for t in edge["targets"]] == [0.9, 0.6] and det.refiner.seen[0].shape[0] == 4
    np.testing.assert_allclose([t["box"] for t in edge["targets"]], [t["box"] for t in high["targets"]], rtol=1e-12)
    for t, u in zip(high["targets"], plain["targets"]):  # the reported boxes did move: the two looks' mean moves
        w = u["box"][2] - u["box"][0]                      # (0.05 and -0.1 left, 0.1 and -0.05 right)
        np.testing.assert_allclose(np.subtract(t["box"], u["box"])[[0, 2]], [-0.025 * w, 0.025 * w], rtol=1e-6)


@pytest.mark.parametrize("style", ["channels", "hot"])
def test_the_record_image_is_the_detector_s_windows_side_by_side(style):
    """What the refiner sees is what the detector saw: each window's image is the record image's columns from its
    first trace (the same record-wide scale), and a record box lands on the same pixels, shifted by that trace."""
    from gpr3d.detection.windows import WindowConfig, prepare, windows

    s = _survey(n_traces=600)
    s.data[:300] *= 5.0  # an uneven record: a per-window scale would show
    cfg = WindowConfig(traces=256, rows=128, overlap=0.25, style=style)
    proc = prepare(s, cfg)
    image = R.record_image(proc, style)
    assert image.shape == (3, 128, 600) and image.dtype == np.float32
    if style == "channels":
        np.testing.assert_array_equal(R.record_image(proc), image)  # the default style
    pm = R.record_pixmap(s, cfg.rows)
    box = np.array([310.0, 1.5e-9, 352.0, 3.0e-9])
    for w in windows(s, cfg, processed=proc):
        np.testing.assert_allclose(image[:, :, w.trace_start : w.trace_start + w.n_traces], w.image[:, :, : w.n_traces],
                                   atol=1e-6)
        np.testing.assert_allclose(np.subtract(pm.box_to_px(box), [w.trace_start, 0, w.trace_start, 0]), w.pixmap.box_to_px(box),
                                   rtol=1e-9, atol=1e-9)


def test_weights_round_trip_and_bad_files_are_one_line(tmp_path):
    net = R.build_refiner()
    p = tmp_path / "r.pt"
    R.save_refiner(net, p, provenance={"data": "none"})
    ref = R.load_refiner(p)
    assert ref.provenance == {"data": "none"}
    x = torch.rand(2, 3, R.CROP, R.CROP)
    with torch.inference_mode():
        np.testing.assert_allclose(ref.net(x).numpy(), net.eval().half().float()(x).numpy(), atol=1e-5)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not torch")
    with pytest.raises(FormatError, match="not a readable weights file"):
        R.load_refiner(bad)
    other = tmp_path / "other.pt"
    torch.save({"format": R.FORMAT, "version": 1, "crop": 32, "expand": R.EXPAND, "state_dict": {}}, other)
    with pytest.raises(FormatError, match="32 px crops"):
        R.load_refiner(other)


def test_onnx_export_gives_pytorch_s_edge_moves(tmp_path, monkeypatch):
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    monkeypatch.chdir(tmp_path)  # nothing but the named files is read or written
    p = tmp_path / "r.pt"
    net = R.build_refiner()
    for m in net.modules():  # a trained-looking network: batch norm statistics not the identity
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.2, 0.2)
            m.running_var.uniform_(0.5, 2.0)
    R.save_refiner(net, p, provenance={"name": "test refiner"})
    r = R.export_refiner_onnx(p, tmp_path / "r.onnx")
    assert r["max_abs_diff"] < 1e-3
    assert r["file"] == str(tmp_path / "r.onnx") and r["bytes"] == (tmp_path / "r.onnx").stat().st_size
    assert not list(tmp_path.glob("*.part"))
    onnx_ref, torch_ref = R.load_refiner(tmp_path / "r.onnx"), R.load_refiner(p)
    assert isinstance(onnx_ref, R.OnnxBoxRefiner)
    assert onnx_ref.provenance == {"name": "test refiner"}
    import hashlib
    import json

    meta = json.loads(onnx_ref.session.get_modelmeta().custom_metadata_map["gpr3d.refiner"])
    assert meta["source_sha256"] == hashlib.sha256(p.read_bytes()).hexdigest() and meta["source_weights"] == "r.pt"
    shipped = R.export_refiner_onnx(out=tmp_path / "shipped.onnx")  # no weights named: the shipped refiner's
    meta = json.loads(R.load_refiner(shipped["file"]).session.get_modelmeta().custom_metadata_map["gpr3d.refiner"])
    # (the shipped refiner's moves on this noise picture reach 0.65 box widths; float kernels differ by 2.5e-3)
    assert meta["source_weights"] == "default_refiner.pt" and shipped["max_abs_diff"] < 5e-3
    assert shipped["max_quality_diff"] < 5e-3 and r["max_quality_diff"] is None
    rng = np.random.default_rng(2)
    image = rng.random((1, 3, 96, 500), dtype=np.float32)
    boxes = np.array([[100, 20, 160, 50], [400, 0, 499, 95], [3, 40, 9, 44]], np.float32)
    got, want = onnx_ref.predict(image, boxes), torch_ref.predict(image, boxes)
    assert got.shape == (3, 4)
    crops = R.crop_array(image[0], boxes).astype(np.float64)  # float64 crops are run in float32 by either engine
    for ref in (onnx_ref, torch_ref):
        np.testing.assert_array_equal(ref.predict_crops(crops), ref.predict_crops(crops.astype(np.float32)))
    for k in (1, 6):  # any number of boxes, any image size: the graph's axes are free
        many = np.tile(boxes, (2, 1))[:k] * np.float32(0.5)
        small = image[:, :, :50, :260]
        np.testing.assert_allclose(onnx_ref.predict(small, many), torch_ref.predict(small, many), atol=1e-3)
    assert np.abs(want).max() > 1e-3
    np.testing.assert_allclose(got, want, atol=1e-3)


def test_the_shipped_refiner_comes_with_the_shipped_detector_in_either_engine(tmp_path):
    pytest.importorskip("onnxruntime")
    from gpr3d.detection.infer import load_detector
    from gpr3d.detection.weights import DEFAULT_WEIGHTS

    onnx_det = load_detector(engine="onnx")
    assert isinstance(onnx_det.refiner, R.OnnxBoxRefiner)
    torch_det = load_detector(engine="torch")
    assert isinstance(torch_det.refiner, R.BoxRefiner) and not isinstance(torch_det.refiner, R.OnnxBoxRefiner)
    assert load_detector(engine="torch", refiner="none").refiner is None
    assert load_detector(DEFAULT_WEIGHTS, engine="torch").refiner is None  # other weights: their own boxes
    assert load_detector(DEFAULT_WEIGHTS, engine="torch", refiner=R.DEFAULT_REFINER).refiner is not None
    # the shipped fine stage comes with the shipped refiner, in its engine; a refiner named by its file comes without
    assert isinstance(onnx_det.refiner.fine, R.OnnxBoxRefiner)
    fine = torch_det.refiner.fine
    assert isinstance(fine, R.BoxRefiner) and not isinstance(fine, R.OnnxBoxRefiner)
    assert fine.provenance["name"] == onnx_det.refiner.fine.provenance["name"] == "refiner_fine_pgpr_5"
    assert fine.rules == ("pgpr",) and len(fine.net.members) == 5 and fine.provenance["jitter_scale"] == 0.5
    assert load_detector(DEFAULT_WEIGHTS, engine="torch", refiner=R.DEFAULT_REFINER).refiner.fine is None
    assert R.load_refiner(fine="none").fine is None and R.load_refiner(engine="onnx", fine=None).fine is None
    fine_meta = onnx_det.refiner.fine.session.get_modelmeta().custom_metadata_map["gpr3d.refiner"]
    crops_ = np.random.default_rng(9).random((3, 3, R.CROP, R.CROP), dtype=np.float32)
    np.testing.assert_allclose(onnx_det.refiner.fine.predict_crops(crops_), fine.predict_crops(crops_), atol=3e-3)
    # the shipped ONNX graph is the export of the shipped weights and moves boxes as they do
    import hashlib

    meta = onnx_det.refiner.session.get_modelmeta().custom_metadata_map["gpr3d.refiner"]
    assert hashlib.sha256(R.DEFAULT_REFINER.read_bytes()).hexdigest() in meta
    assert hashlib.sha256(R.DEFAULT_FINE_REFINER.read_bytes()).hexdigest() in fine_meta
    rng = np.random.default_rng(8)
    image = rng.random((1, 3, 256, 700), dtype=np.float32)
    boxes = np.array([[50, 30, 150, 80], [600, 100, 690, 200]], np.float32)
    # edge moves within 3e-3 (1.2e-3 measured on this noise picture, far from any radargram, with the whole-hyperbola
    # refiner; 1.1e-3 with the one of two rules and quality heads; the refiner shipped before it moves these boxes
    # 0.10 away), and the predicted IoUs too (their logits 7e-3 apart on this picture: 1.8e-3 in IoU at most)
    got, want = onnx_det.refiner.predict(image, boxes), torch_det.refiner.predict(image, boxes)
    width = 4 + int(torch_det.refiner.quality)
    moves = [c for c in range(want.shape[1]) if c % width < 4]
    np.testing.assert_allclose(got[:, moves], want[:, moves], atol=3e-3)
    if torch_det.refiner.quality:
        np.testing.assert_allclose(1 / (1 + np.exp(-got[:, 4::width])), 1 / (1 + np.exp(-want[:, 4::width])), atol=3e-3)
    # its session's threads sleep between runs (a spinning second pool beside the detector's slowed its network)
    opts = onnx_det.refiner.session.get_session_options()
    assert opts.get_session_config_entry("session.intra_op.allow_spinning") == "0"
    assert opts.intra_op_num_threads == 0  # (ONNX Runtime's choice: a thread per core)
    # refine() hands either engine float32 pictures and boxes, whatever it is given
    s = _survey(n_traces=700, n_samples=256)
    img64 = rng.random((3, 256, 700))
    rec = np.array([[50.0, 1e-9, 150.0, 3e-9], [600.0, 4e-9, 690.0, 8e-9]])
    pm = R.record_pixmap(s, 256)

    def px(boxes):
        return np.array([pm.box_to_px(b) for b in boxes])

    # compared in pixels, one pass (both looks), in shares of each box's sides: the two engines' networks round
    # apart on the same crops (on this picture 1.3e-3 of a side measured with the refiner of two rules and quality
    # heads, 1.3e-4 with the one before it; 2.6e-3 at most over the 55 boxes of the real DZT, 9e-4 before). A
    # second pass crops where each engine's first pass put the boxes and amplifies that unevenly
    onnx_det.refiner.passes = torch_det.refiner.passes = 1
    a, b = px(onnx_det.refiner.refine(s, 256, rec, img64)), px(torch_det.refiner.refine(s, 256, rec, img64))
    sides = np.tile(b[:, 2:] - b[:, :2], 2)
    assert (np.abs(a - b) <= 3e-3 * sides).all(), np.abs(a - b) / sides


@pytest.mark.slow
def test_the_shipped_refiner_brings_boxes_closer_to_real_labels():
    """P-GPR's validation B-scans (real, 1.6 GHz, two radars; never trained on): over their labels, the best
    overlap a refined box reaches is higher than the network's own boxes reach (measured with the shipped
    refiner: 0.667 -> 0.713 on AIR's radar, 0.738 -> 0.751 on IECAS's; the margin asked is half the gain)."""
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.yolo import read_yolo
    from tests.conftest import real_file

    records = read_yolo(real_file("pgpr_1600MHz/val"), names=["steel", "pipe"],
                        kinds="pipe=pvc_pipe", pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9)
    plain, refined = load_detector(refiner="none"), load_detector()
    best = {"plain": [], "refined": []}
    for survey, labels in records:
        px = np.array([1.0, 1 / survey.dt_s, 1.0, 1 / survey.dt_s])
        truth = np.array([np.asarray(x["box"]) * px for x in labels["labels"]]).reshape(-1, 4)
        for name, det in (("plain", plain), ("refined", refined)):
            found = det.detect(survey, score_threshold=0.5)["targets"]
            boxes = np.array([np.asarray(x["box"]) * px for x in found]).reshape(-1, 4)
            best[name] += list(R.pair_iou(truth[:, None, :], boxes[None, :, :]).max(axis=1, initial=0.0))
    a, b = np.mean(best["plain"]), np.mean(best["refined"])
    assert b > a + 0.015, (a, b)


def test_pair_iou_against_hand_values_and_broadcast():
    a = np.array([[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 4.0, 2.0], [5.0, 5.0, 5.0, 9.0]])
    b = np.array([[5.0, 0.0, 15.0, 10.0], [2.0, 1.0, 6.0, 3.0], [5.0, 5.0, 5.0, 9.0]])
    # half overlap: 50 / 150; 2 x 1 = 2 of 8 + 8 - 2 = 14; zero-area boxes: 0, not nan
    np.testing.assert_allclose(R.pair_iou(a, b), [50 / 150, 2 / 14, 0.0])
    m = R.pair_iou(a[:, None, :], b[None, :, :])
    assert m.shape == (3, 3)
    np.testing.assert_allclose(np.diag(m), R.pair_iou(a, b))
    np.testing.assert_allclose(m[0, 1], 8 / 100)  # [2, 1, 6, 3] lies inside the first box
    # away from the origin, apart on both axes, and smaller than a pixel
    a = np.array([[10.0, 20.0, 14.0, 23.0], [0.0, 0.0, 1.0, 1.0], [0.1, 0.1, 0.5, 0.5]])
    b = np.array([[12.0, 21.0, 16.0, 25.0], [3.0, 3.0, 5.0, 5.0], [0.3, 0.3, 0.7, 0.7]])
    # 2 x 2 = 4 of 12 + 16 - 4; no overlap (not the product of two negative overlaps); 0.04 of 0.28
    np.testing.assert_allclose(R.pair_iou(a, b), [4 / 24, 0.0, 0.04 / 0.28])
    np.testing.assert_allclose(R.pair_iou(b, a), R.pair_iou(a, b))
    # apart on one axis only: no overlap (not a negative one)
    a = np.array([[0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0]])
    b = np.array([[3.0, 0.0, 5.0, 1.0], [0.0, 3.0, 1.0, 5.0]])
    np.testing.assert_array_equal(R.pair_iou(a, b), [0.0, 0.0])


def test_onnx_refiner_files_that_are_not_refiners_are_one_line(tmp_path):
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from gpr3d.detection.ort import NMS_ONNX
    from gpr3d.io.onnxweights import finish_export

    with pytest.raises(FormatError, match=r"gone\.onnx: no such ONNX refiner file"):
        R.load_refiner(tmp_path / "gone.onnx")
    (tmp_path / "junk.onnx").write_bytes(b"not onnx")
    with pytest.raises(FormatError, match=r"junk\.onnx: not a readable ONNX refiner \("):
        R.load_refiner(tmp_path / "junk.onnx")
    with pytest.raises(FormatError, match=r"nms\.onnx: an ONNX file without gpr3d refiner metadata"):
        R.load_refiner(NMS_ONNX)
    import shutil

    for name, meta, msg in [("crop.onnx", {"crop": 32, "expand": R.EXPAND}, "a refiner for 32 px crops x 2.0"),
                            ("expand.onnx", {"crop": R.CROP, "expand": 3.0}, "a refiner for 64 px crops x 3.0")]:
        shutil.copy(NMS_ONNX, tmp_path / name)
        finish_export(tmp_path / name, "gpr3d.refiner", meta)
        with pytest.raises(FormatError, match=rf"{name}: {msg}, this gpr3d makes 64 px x 2.0"):
            R.load_refiner(tmp_path / name)
    from onnx import TensorProto, helper

    def graph(inputs):  # a graph taking these inputs, with a refiner's metadata
        g = helper.make_graph([helper.make_node("Identity", [inputs[0]], ["deltas"])], "g",
                              [helper.make_tensor_value_info(n, TensorProto.FLOAT, ["n", 4]) for n in inputs],
                              [helper.make_tensor_value_info("deltas", TensorProto.FLOAT, ["n", 4])])
        path = tmp_path / f"{'_'.join(inputs)}.onnx"
        onnx.save(helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)]), str(path))
        finish_export(path, "gpr3d.refiner", {"crop": R.CROP, "expand": R.EXPAND})
        return path

    onnx = pytest.importorskip("onnx")
    with pytest.raises(FormatError, match=r"image_boxes\.onnx: a refiner graph taking image, boxes \(an export of "
                                          r"an older gpr3d, which cropped inside the graph\); export its weights again"):
        R.load_refiner(graph(["image", "boxes"]))
    ok = R.load_refiner(graph(["crops"]))  # no provenance written: none
    assert ok.provenance == {}
    np.testing.assert_array_equal(ok.predict_crops(np.ones((2, 4))), np.ones((2, 4)))


def test_refiner_weights_that_do_not_fit_are_one_line(tmp_path):
    net = R.build_refiner()
    net[-1] = torch.nn.Linear(256, 5)  # a refiner with a fifth output (an earlier quality variant)
    obj = {"format": R.FORMAT, "version": 1, "crop": R.CROP, "expand": R.EXPAND, "outputs": 5, "rescore": 0.5,
           "state_dict": {k: v.half() for k, v in net.state_dict().items()}}
    torch.save(obj, tmp_path / "five.pt")
    with pytest.raises(RuntimeError) as direct:  # what PyTorch says of the same weights
        R.build_refiner().load_state_dict({k: v.float() for k, v in obj["state_dict"].items()})
    with pytest.raises(FormatError) as err:
        R.load_refiner(tmp_path / "five.pt")
    last = str(direct.value).splitlines()[-1].strip()
    assert "size mismatch" in last and str(err.value) == f"five.pt: weights do not fit the refiner: {last[:160]}"
    extra = dict(obj, state_dict=dict(R.build_refiner().half().state_dict(), **{"x" * 300: torch.zeros(1)}))
    torch.save(extra, tmp_path / "long.pt")  # an unexpected key: PyTorch's line is long, ours stops at 160
    with pytest.raises(FormatError) as err:
        R.load_refiner(tmp_path / "long.pt")
    assert len(str(err.value)) == len("long.pt: weights do not fit the refiner: ") + 160
    torch.save(dict(obj, crop=R.CROP, expand=3.0), tmp_path / "x3.pt")
    with pytest.raises(FormatError, match=r"x3\.pt: a refiner for 64 px crops x 3.0, this gpr3d makes 64 px x 2.0"):
        R.load_refiner(tmp_path / "x3.pt")
    old = {k: v for k, v in obj.items() if k not in ("outputs", "rescore")}  # keys this gpr3d does not need
    old["state_dict"] = {k: v.half() for k, v in R.build_refiner().state_dict().items()}
    torch.save(old, tmp_path / "old.pt")
    ref = R.load_refiner(tmp_path / "old.pt")
    assert ref.provenance == {} and ref.net[-1].out_features == 4
    x = torch.rand(1, 3, R.CROP, R.CROP)
    with torch.inference_mode():  # float16 on disk, float32 in the network
        assert ref.net[0][0].weight.dtype == torch.float32
        np.testing.assert_allclose(ref.net(x).numpy(), R.build_refiner().half().float().eval()(x).numpy(), atol=1e-5)
    with pytest.raises(FormatError, match=r"gone\.pt: no such box refiner weights file"):
        R.load_refiner(tmp_path / "gone.pt")


def test_mirror_deltas_swap_the_side_edges_and_turn_them_round():
    d = np.array([[0.1, -0.2, 0.3, 0.4], [-0.05, 0.0, 0.0, -0.1]])
    np.testing.assert_array_equal(R.mirror_deltas(d), [[-0.3, -0.2, -0.1, 0.4], [0.0, 0.0, 0.05, -0.1]])
    np.testing.assert_array_equal(R.mirror_deltas(R.mirror_deltas(d)), d)


class _ToBrightest:
    """A refiner whose network centres each box on the brightest part of its crop (the centroid of the first
    channel's column sums) and moves its bottom down by a tenth of its height: it sees only the crop, so it is
    mirror-equivariant by construction."""

    provenance = {"name": "to the brightest column"}

    def __init__(self, mirror, passes):
        self.mirror, self.passes, self.seen = mirror, passes, []

    def predict_crops(self, crops):
        self.seen.append(crops.copy())
        cols = crops[:, 0].sum(axis=1)  # (n, CROP)
        at = (cols * np.arange(R.CROP)).sum(axis=1) / cols.sum(axis=1)
        shift = ((at + 0.5) / R.CROP - 0.5) * R.EXPAND  # bin i's centre, in box widths from the box's centre
        return np.stack([shift, np.zeros(len(at)), shift, np.full(len(at), 0.1)], axis=1)

    rules, quality, rule, quality_weight, fine = (), False, "auto", R.QUALITY_WEIGHT, None  # one head, no quality
    refine, refine_scored, head_for = R.BoxRefiner.refine, R.BoxRefiner.refine_scored, R.BoxRefiner.head_for
    fine_for = R.BoxRefiner.fine_for
    weight_for = R.BoxRefiner.weight_for


def test_a_mirrored_look_averages_the_box_s_moves_with_its_mirror_image_s():
    s = _survey(n_traces=300)
    rows = 128
    image = np.zeros((3, rows, 300), np.float32)
    image[:, :, 166:177] = 1.0  # traces 166..176: the bright band, about trace 171 (pixel 171.5)
    boxes = np.array([[140.0, 1e-9, 180.0, 2e-9], [150.0, 0.5e-9, 210.0, 3e-9]])
    one = _ToBrightest(False, 1).refine(s, rows, boxes, image)
    np.testing.assert_allclose(0.5 * (one[:, 0] + one[:, 2]), 171.0, atol=0.3)  # to a fraction of a crop's bin
    np.testing.assert_allclose(one[:, 2] - one[:, 0], boxes[:, 2] - boxes[:, 0])
    np.testing.assert_allclose(one[:, 3] - boxes[:, 3], 0.1 * (boxes[:, 3] - boxes[:, 1]), rtol=1e-9)
    ref = _ToBrightest(True, 1)
    both = ref.refine(s, rows, boxes, image)
    np.testing.assert_allclose(both, one, rtol=1e-9, atol=1e-15)  # an equivariant network: the mirror changes nothing
    crops, = ref.seen  # both looks in one batch: the crops, then the same crops mirrored
    assert crops.shape == (4, 3, R.CROP, R.CROP)
    np.testing.assert_array_equal(crops[2:], crops[:2, ..., ::-1])
    # ... and a network that always moves boxes right moves them neither way when the two looks are averaged
    right = _Fixed([0.1, 0.0, 0.1, 0.2])
    right.mirror = True
    got = right.refine(s, rows, boxes, image)
    np.testing.assert_allclose(got[:, [0, 2]], boxes[:, [0, 2]], atol=1e-9)
    np.testing.assert_allclose(got[:, 3] - boxes[:, 3], 0.2 * (boxes[:, 3] - boxes[:, 1]), rtol=1e-6)
    np.testing.assert_allclose(got[:, 1], boxes[:, 1], rtol=1e-6)


def test_each_pass_starts_from_the_box_the_one_before_moved():
    s = _survey(n_traces=300)
    rows = 256
    image = _coordinates(rows, 300)
    target = np.array([100.0, 50.0, 180.0, 110.0])  # pixels

    class Halfway(_Fixed):
        def predict_crops(self, crops):  # half of the way to the target, every edge, from the box it reads
            self.seen.append(crops.copy())
            boxes = np.array([_box_of(c) for c in crops])
            return 0.5 * R.box_deltas(boxes, np.repeat(target[None], len(boxes), 0))

    pm = R.record_pixmap(s, rows)
    start = np.array([60.0, 60.0, 150.0, 140.0])
    box = np.array([pm.px_to_box(start)])
    for passes in (1, 2, 3):
        ref = Halfway(np.zeros(4))
        ref.passes = passes
        got = np.array(pm.box_to_px(ref.refine(s, rows, box, image)[0]))
        np.testing.assert_allclose(got, target + (start - target) / 2**passes, rtol=1e-4)
        assert len(ref.seen) == passes
        np.testing.assert_allclose(_box_of(ref.seen[0][0]), start, rtol=1e-4)
        if passes > 1:
            np.testing.assert_allclose(_box_of(ref.seen[1][0]), 0.5 * (start + target), rtol=1e-4)


def test_the_shipped_refiner_gives_a_mirrored_picture_mirrored_boxes():
    """With the mirrored look (the default) the shipped network's boxes of a real P-GPR picture seen mirrored are
    the mirror images of its boxes of the picture (to float rounding), in one pass or two; with one look they are
    not (the network was trained on mirrored crops but is not exactly symmetric)."""
    from gpr3d.data import example_pgpr
    from gpr3d.detection.windows import WindowConfig, prepare
    from gpr3d.io.yolo import read_yolo

    (survey, labels), = read_yolo(example_pgpr(), names=["steel", "pipe"], kinds="pipe=pvc_pipe",
                                  pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9)
    cfg = WindowConfig()
    image = R.record_image(prepare(survey, cfg), cfg.style)
    n = survey.n_traces
    boxes = np.array([x["box"] for x in labels["labels"]], float)
    rng = np.random.default_rng(11)
    h = boxes[:, 3] - boxes[:, 1]
    boxes = boxes + np.stack([rng.normal(0, 2, len(boxes)), rng.normal(0, 0.1, len(boxes)) * h,
                              rng.normal(0, 2, len(boxes)), rng.normal(0, 0.1, len(boxes)) * h], 1)

    def flip(b):
        return np.stack([n - 1 - b[:, 2], b[:, 1], n - 1 - b[:, 0], b[:, 3]], axis=1)

    gaps = {}
    for mirror, passes in ((True, 1), (True, 2), (False, 1)):
        ref = R.load_refiner(mirror=mirror, passes=passes)
        a = ref.refine(survey, cfg.rows, boxes, image)
        b = flip(ref.refine(survey, cfg.rows, flip(boxes), np.ascontiguousarray(image[..., ::-1])))
        px = np.array([1.0, 1 / survey.dt_s, 1.0, 1 / survey.dt_s])  # traces and samples
        gaps[mirror, passes] = float(np.abs((a - b) * px).max())
        assert np.abs((a - boxes) * px).max() > 0.3  # the boxes did move
    print("GAPS", gaps)
    assert gaps[True, 1] < 2e-3 and gaps[True, 2] < 2e-3, gaps
    assert gaps[False, 1] > 0.05, gaps


@pytest.mark.parametrize("mirror, passes, what", [
    (True, 0, "passes must be a whole number in 1..5, got 0"), (True, 6, "got 6"), (True, 1.5, "got 1.5"),
    (True, True, "got True"), ("yes", 2, "mirror setting must be True or False, got 'yes'")])
def test_how_a_refiner_is_applied_is_checked_in_one_line(mirror, passes, what, tmp_path):
    from gpr3d.detection.infer import load_detector

    with pytest.raises(InvalidDataError, match=what):
        R.load_refiner(tmp_path / "never_read.pt", mirror=mirror, passes=passes)  # before the file is read
    with pytest.raises(InvalidDataError, match=what):
        load_detector(tmp_path / "never_read.pt", refiner="default", refine_mirror=mirror, refine_passes=passes)
    ref = R.load_refiner()
    assert (ref.mirror, ref.passes) == (R.MIRROR, R.PASSES) == (True, 2)  # the shipped way
    assert R.load_refiner(passes=R.MAX_PASSES).passes == 5  # the most passes allowed
    for m, p in ((None, None), (False, None), (None, 3), (False, 1)):  # each setting given alone reaches the refiner
        r = load_detector(engine="torch", refine_mirror=m, refine_passes=p).refiner
        assert (r.mirror, r.passes) == (True if m is None else m, 2 if p is None else p)
    ref.passes = passes if passes != 0 else -1
    ref.mirror = mirror
    with pytest.raises(InvalidDataError, match="the refiner's"):  # settings changed afterwards are checked too
        ref.refine(_survey(), 128, np.array([[10.0, 1e-9, 40.0, 2e-9]]), np.zeros((3, 128, 300), np.float32))


def test_whole_boxes_mirror_a_cut_box_about_its_apex():
    """A box cut by the first trace reaches as far before it as its right edge lies after the apex; one cut by the
    last trace likewise after it; boxes cut on both sides or on none are left as they are."""
    boxes = [[0.0, 1.0, 30.0, 2.0],     # cut by trace 0, apex 12: whole from 12 - 18 = -6
             [70.0, 1.0, 99.0, 2.0],    # cut by the last trace (99 of 100), apex 90: whole to 90 + 20 = 110
             [0.0, 1.0, 99.0, 2.0],     # both ends: unknown
             [20.0, 1.0, 40.0, 2.0],    # inside
             [0.4, 1.0, 10.0, 2.0]]     # within half a trace of the first: cut; apex 9 -> whole from 8
    whole = R.whole_boxes(boxes, [12.0, 90.0, 50.0, 30.0, 9.0], 100)
    np.testing.assert_allclose(whole, [[-6.0, 1.0, 30.0, 2.0], [70.0, 1.0, 110.0, 2.0], [0.0, 1.0, 99.0, 2.0],
                                       [20.0, 1.0, 40.0, 2.0], [0.4, 1.0, 10.0, 2.0]])
    # the last: its mirror (8.0) lies inside the box, so the box keeps its own edge (a box never shrinks)
    np.testing.assert_allclose(R.whole_boxes([[0.0, 0, 10.0, 1]], [3.0], 100), [[-4.0, 0, 10.0, 1]])
    assert np.asarray(boxes).tolist()[0] == [0.0, 1.0, 30.0, 2.0]  # the input is not changed
    # the ends' bounds exactly: 0.5 is cut, 1.0 is not; 98.5 (n - 1.5) is cut, 98.0 is not; a box inside with its
    # apex off its centre stays; a right-cut box whose mirror lies inside keeps its right edge (not its bottom)
    edges = R.whole_boxes([[0.5, 0, 20.0, 1], [1.0, 0, 20.0, 1], [60.0, 0, 98.5, 1], [60.0, 0, 98.0, 1],
                           [20.0, 0, 40.0, 1], [70.0, 1.0, 99.0, 150.0]], [5.0, 5.0, 90.0, 90.0, 25.0, 80.0], 100)
    np.testing.assert_allclose(edges, [[-10.0, 0, 20.0, 1], [1.0, 0, 20.0, 1], [60.0, 0, 120.0, 1],
                                       [60.0, 0, 98.0, 1], [20.0, 0, 40.0, 1], [70.0, 1.0, 99.0, 150.0]])
    # integer boxes and a column of apexes give the same float boxes
    got = R.whole_boxes(np.array([[0, 1, 30, 2], [0, 1, 40, 2]]), np.array([[12.25], [15.0]]), 100)
    assert got.dtype == float
    np.testing.assert_allclose(got, [[-5.5, 1, 30, 2], [-10.0, 1, 40, 2]])


def test_the_apex_of_a_whole_box_is_its_centre_where_it_reaches_past_one_end():
    assert R.whole_apex([-6.0, 0, 30.0, 1], 100) == 12.0
    assert R.whole_apex([70.0, 0, 110.0, 1], 100) == 90.0
    assert R.whole_apex([80.0, 0, 140.0, 1], 100) == 99.0  # a centre past the end is kept inside the record
    assert R.whole_apex([-0.9, 0, 30.0, 1], 100) is None  # less than a trace past: the label rule's apex
    assert R.whole_apex([-1.5, 0, 30.0, 1], 100, reach=2.0) is None
    assert R.whole_apex([-1.5, 0, 30.0, 1], 100) == 14.25
    assert R.whole_apex([20.0, 0, 40.0, 1], 100) is None and R.whole_apex([-5.0, 0, 105.0, 1], 100) is None
    # exactly a trace past is not past; just inside the last trace is not past; past the first, a centre before
    # trace 0 is kept at 0
    assert R.whole_apex([-1.0, 0, 30.0, 1], 100) is None and R.whole_apex([50.0, 0, 100.0, 1], 100) is None
    assert R.whole_apex([50.0, 0, 99.5, 1], 100) is None
    assert R.whole_apex([60.0, 0, 101.5, 1], 100) == 80.75
    assert R.whole_apex([-50.0, 0, 10.0, 1], 100) == 0.0


class _Whole:
    provenance = {"name": "whole", "whole": True}


def test_a_refiner_is_one_of_whole_hyperbolas_only_where_its_provenance_says_so():
    assert R.BoxRefiner.whole.fget(_Whole()) is True
    assert R.BoxRefiner.whole.fget(_Fixed([0, 0, 0, 0])) is False
    assert R.load_refiner().whole is True and R.load_refiner(engine="onnx").whole is True  # the shipped one
    assert R.BoxRefiner.whole.fget(type("Old", (), {"provenance": {"name": "x"}})()) is False  # (before --whole)


def test_a_whole_refiner_s_box_past_the_first_trace_gives_its_apex_as_its_centre():
    """The detector's apex of a box the refiner moved past the record's first trace is that box's centre when the
    refiner learned whole hyperbolas, and the label rule's (from the box cut to the record) when it did not; the
    box reported is the one cut to the record either way."""
    from gpr3d.detection.windows import WindowConfig

    s = _survey(n_traces=256)
    cfg = WindowConfig(traces=256, rows=128, overlap=0.0)
    det = _one_box_detector(cfg, boxes=[[0.0, 30.0, 60.0, 60.0], [150.0, 30.0, 200.0, 60.0]], scores=[0.9, 0.8])
    det.refiner = _Fixed([-1.0, 0.0, 0.0, 0.0])  # the left edge one box width further left: past trace 0
    rule = det.detect(s)["targets"]
    det.refiner.provenance = {"name": "fixed moves", "whole": True}
    det.refiner.whole = True
    whole = det.detect(s)["targets"]
    assert len(rule) == len(whole) == 2
    np.testing.assert_allclose([t["box"] for t in whole], [t["box"] for t in rule], rtol=1e-12)
    # the second box stays inside the record (moved to traces 99.5..199.5): the label rule's apex, its centre
    assert whole[1]["apex_trace"] == rule[1]["apex_trace"] == 150
    assert whole[0]["box"][0] == 0.0  # reported cut to the record
    # the network's box: pixels 0..60 are traces -0.5..59.5; moved one width left: -60.5..59.5, centre -0.5 -> 0
    assert whole[0]["apex_trace"] == 0
    assert rule[0]["apex_trace"] != whole[0]["apex_trace"]
    assert whole[0]["apex_time_s"] == rule[0]["apex_time_s"]


def _cut_records(n, rng, rows=64, cols=120):
    """Images each holding a bright 'V' (a hyperbola's legs) cut by the first column; the label box is the V cut to
    the picture, the whole box the V's own, whose centre is its apex column."""
    out = []
    for _ in range(n):
        img = rng.normal(0, 0.05, (3, rows, cols)).astype(np.float32)
        apex, half, top = rng.uniform(2, 14), rng.uniform(16, 26), rng.uniform(6, 16)
        for c in range(cols):
            if abs(c + 0.5 - apex) <= half:
                r = int(top + 0.8 * abs(c + 0.5 - apex))
                img[:, r : r + 3, c] += 1.0
        bottom = top + 0.8 * half + 3
        whole = np.array([[apex - half, top, apex + half, bottom]])
        out.append((img, np.array([[0.5, top, apex + half, bottom]]), whole))
    return out


def test_training_on_whole_boxes_teaches_the_refiner_to_reach_past_the_picture():
    """Trained with whole target boxes, the refiner moves a box cut to the picture past its first column, and that
    box's centre finds the apex better than the cut box's rule-free centre; trained on the cut labels alone, it
    does not reach past."""
    rng = np.random.default_rng(0)
    train = _cut_records(60, rng)
    whole_net = R.BoxRefiner(R.train_refiner(train, epochs=6, per_label=12, batch=64))
    cut_net = R.BoxRefiner(R.train_refiner([(i, lab) for i, lab, _ in train], epochs=6, per_label=12, batch=64))
    err_whole, err_cut, reach_cut = [], [], []
    for img, label, whole in _cut_records(20, np.random.default_rng(1)):
        apex = 0.5 * (whole[0, 0] + whole[0, 2])
        start = label.astype(np.float32)
        moved = R.apply_deltas(start, whole_net.predict(img[None], start))
        err_whole.append(abs(0.5 * (moved[0, 0] + moved[0, 2]) - apex))
        err_cut.append(abs(0.5 * (start[0, 0] + start[0, 2]) - apex))
        reach_cut.append(R.apply_deltas(start, cut_net.predict(img[None], start))[0, 0])
    # (measured: 0.69 trace against 7.6; a refiner taught the cut labels instead stays within 1.5 traces of them)
    assert np.median(err_whole) < 0.3 * np.median(err_cut), (np.median(err_whole), np.median(err_cut))
    assert np.median(reach_cut) > -3.0  # the cut labels' refiner keeps the edge near the picture's


def test_whole_targets_are_learned_from_boxes_drawn_about_them_half_cut_to_the_picture(monkeypatch):
    """What ``train_refiner`` crops and aims at for a sample with whole target boxes: boxes drawn about the whole
    box, half of them cut to the record's traces (left edge within pixels 0.5..cols - 2.5, right edge at most cols -
    0.5 and at least 2 pixels right of the left), the target the whole box itself."""
    seen = {}
    real_crops, real_deltas = R.crops, R.box_deltas

    def spy_crops(image, boxes):
        seen.setdefault("boxes", []).append(np.array(boxes))
        return real_crops(image, boxes)

    def spy_deltas(boxes, targets):
        seen.setdefault("targets", []).append(np.array(targets))
        return real_deltas(boxes, targets)

    monkeypatch.setattr(R, "crops", spy_crops)
    monkeypatch.setattr(R, "box_deltas", spy_deltas)
    img = np.zeros((3, 40, 50), np.float32)
    cases = [([[0.5, 5.0, 20.0, 15.0]], [[-10.0, 5.0, 20.0, 15.0]]),    # cut by the first trace
             ([[46.0, 5.0, 49.5, 15.0]], [[46.0, 5.0, 60.0, 15.0]]),    # by the last, its left edge near it
             ([[0.5, 5.0, 2.5, 15.0]], [[-30.0, 5.0, -20.0, 15.0]])]    # wholly before the picture
    R.train_refiner([(img, np.array(lab), np.array(whole)) for lab, whole in cases], epochs=1, per_label=400,
                    batch=4000)
    for k, (lab, whole) in enumerate(cases):
        jb, tg = seen["boxes"][k], seen["targets"][k]
        np.testing.assert_array_equal(tg, np.repeat(whole, 400, axis=0))  # aimed at the whole box
        cut = (jb[:, 0] >= 0.5) & (jb[:, 0] <= 47.5) & (jb[:, 2] <= 49.5) & (jb[:, 2] >= jb[:, 0] + 2)
        if k == 0:
            assert 0.4 < np.mean(jb[:, 0] == 0.5) < 0.6  # half cut to the first pixel
            assert np.mean(jb[:, 0] < 0) > 0.4  # the others drawn about the whole box, past it
        if k == 1:
            assert 0.4 < np.mean(jb[:, 2] == 49.5) < 0.6
            assert jb[jb[:, 2] == 49.5, 0].max() == 47.5  # a cut box's left edge stops 2 pixels short of the end
            assert np.all(jb[cut, 2] == 49.5)
        if k == 2:
            assert 0.4 < np.mean(cut) < 0.6
            np.testing.assert_array_equal(jb[cut, 0], 0.5)
            np.testing.assert_array_equal(jb[cut, 2], 2.5)  # at least 2 pixels wide
            assert np.all(jb[~cut, 2] < -10)


# --- label rules' heads and the quality head -------------------------------------------------------------------

def test_best_iou_is_each_box_s_largest_iou_with_a_label_cut_to_the_picture_first():
    labels = np.array([[10.0, 0.0, 20.0, 10.0], [30.0, 0.0, 50.0, 10.0]])
    boxes = np.array([[10.0, 0.0, 20.0, 10.0],   # on the first label
                      [15.0, 0.0, 25.0, 10.0],   # half on the first: 50 / 150
                      [35.0, 0.0, 45.0, 10.0],   # inside the second: 100 / 200
                      [60.0, 0.0, 70.0, 10.0],   # on none
                      [-10.0, 0.0, 20.0, 10.0]])  # past the picture's first column: cut to 0..20
    np.testing.assert_allclose(R.best_iou(boxes, labels), [1.0, 1 / 3, 0.5, 0.0, 1 / 3])
    np.testing.assert_allclose(R.best_iou(boxes, labels, cols=100)[4], 0.5)  # 0..20 against 10..20
    assert R.best_iou(boxes, np.zeros((0, 4))).tolist() == [0.0] * 5


class _TwoRules:
    """A refiner of two heads with quality: the gpr3d head moves the left edge a tenth of the width right, the
    P-GPR head a tenth left; the quality logit is how much brighter the crop's left half is than its right
    (mirrored, the opposite)."""

    provenance = {"name": "two rules", "rules": ["gpr3d", "pgpr"], "quality": True}
    mirror, passes, rule, quality_weight = False, 1, "auto", 1.0
    rules, quality, fine, whole = ("gpr3d", "pgpr"), True, None, False
    refine, refine_scored, head_for = R.BoxRefiner.refine, R.BoxRefiner.refine_scored, R.BoxRefiner.head_for
    fine_for = R.BoxRefiner.fine_for
    weight_for = R.BoxRefiner.weight_for

    def predict_crops(self, crops):
        half = R.CROP // 2
        logit = 4.0 * (crops[:, 0, :, :half].mean(axis=(1, 2)) - crops[:, 0, :, half:].mean(axis=(1, 2)))
        z = np.zeros(len(crops))
        return np.stack([z + 0.1, z, z, z, logit, z - 0.1, z, z, z, logit + 1.0], axis=1)


def test_a_refiner_of_two_rules_takes_the_head_of_the_record_s_kind_and_scores_with_its_quality():
    s = _survey()
    rows = 256
    image = np.zeros((3, rows, s.n_traces), np.float32)
    image[:, :, :150] = 1.0  # left half of the record bright
    box = np.array([[120.0, 2e-9, 160.0, 4e-9]])  # straddles the edge: its crop's left half brighter
    ref = _TwoRules()
    moved, q = ref.refine_scored(s, rows, box, image)
    np.testing.assert_allclose(moved[0, 0], 124.0, rtol=1e-9)  # a recording: gpr3d's head
    crop = R.crop_array(image, np.array([R.record_pixmap(s, rows).box_to_px(b) for b in moved]))
    a = 4.0 * (crop[0, 0, :, : R.CROP // 2].mean() - crop[0, 0, :, R.CROP // 2 :].mean())
    assert a > 0.5
    np.testing.assert_allclose(q, [1 / (1 + np.exp(-a))], rtol=1e-5)  # the last look, at the moved box
    picture = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": "picture"})
    moved_p, q_p = ref.refine_scored(picture, rows, box, image)
    np.testing.assert_allclose(moved_p[0, 0], 116.0, rtol=1e-9)  # a picture: P-GPR's head
    assert q_p[0] > q[0] - 1e-9
    ref.rule = "gpr3d"  # told which: that head, whatever the input
    np.testing.assert_allclose(ref.refine(picture, rows, box, image)[0, 0], 124.0, rtol=1e-9)
    ref.rule, ref.mirror = "auto", True  # both looks: the moves averaged with the mirror's, the qualities too
    both, q_m = ref.refine_scored(s, rows, box, image)
    np.testing.assert_allclose(both[0, 0], 120.0 + 0.5 * (0.1 * 40 - 0.0 * 40), rtol=1e-9)
    np.testing.assert_allclose(q_m, [0.5], atol=1e-6)  # sigmoid(a) and sigmoid(-a) average to one half
    assert ref.refine_scored(s, rows, box, image, score=False)[1] is None
    ref.rule = "nobody's"
    with pytest.raises(InvalidDataError, match="^box rule must be auto or one of gpr3d, pgpr, got \"nobody's\"$"):
        ref.refine(s, rows, box, image)


def test_the_detector_multiplies_refined_scores_by_the_quality_to_its_weight_and_says_how():
    from gpr3d.detection.windows import WindowConfig

    s = _survey(n_traces=256)
    cfg = WindowConfig(traces=256, rows=128, overlap=0.0)
    det = _one_box_detector(cfg, boxes=[[40.0, 30.0, 90.0, 60.0], [150.0, 20.0, 200.0, 70.0]], scores=[0.9, 0.3])

    class Half(_TwoRules):
        def predict_crops(self, crops):
            out = super().predict_crops(crops)
            out[:, [4, 9]] = 0.0  # quality one half everywhere
            return out

    det.refiner = Half()
    plain = _one_box_detector(cfg, boxes=[[40.0, 30.0, 90.0, 60.0], [150.0, 20.0, 200.0, 70.0]],
                              scores=[0.9, 0.3]).detect(s, score_threshold=0.0)
    got = det.detect(s, score_threshold=0.0)
    assert got["refine"] == {"mirror": False, "passes": 1, "fine": None, "duplicate_iou": 0.5, "rule": "gpr3d",
                             "quality_weight": 1.0}
    assert sorted(t["score"] for t in got["targets"]) == pytest.approx([0.15, 0.45])
    det.refiner.quality_weight = 2.0
    assert sorted(t["score"] for t in det.detect(s, score_threshold=0.0)["targets"]) == pytest.approx([0.075, 0.225])
    det.refiner.quality_weight = 0.0  # weight 0: the network's scores, and no last look is taken
    assert sorted(t["score"] for t in det.detect(s, score_threshold=0.0)["targets"]) == \
        sorted(t["score"] for t in plain["targets"])
    det.refiner.quality_weight = 1.0
    # only the boxes at or above the threshold are refined and rescaled; rescaled below it, they are not reported
    assert det.detect(s, score_threshold=0.5)["targets"] == []
    assert [t["score"] for t in det.detect(s, score_threshold=0.4)["targets"]] == pytest.approx([0.45])
    # no weight given: the refiner's own (1 here) for simulated records, none for a real radar's recording
    det.refiner.quality_weight = None
    det.refiner.provenance = {"name": "two rules", "rules": ["gpr3d", "pgpr"], "quality": True}
    det.refiner.weight_for = R.BoxRefiner.weight_for.__get__(det.refiner)
    assert sorted(t["score"] for t in det.detect(s, score_threshold=0.0)["targets"]) == pytest.approx([0.15, 0.45])
    for fmt in ("dzt", "dt1", "rd3", "segy"):
        real = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": fmt})
        got = det.detect(real, score_threshold=0.0)
        assert got["refine"]["quality_weight"] == 0.0, fmt
        assert sorted(t["score"] for t in got["targets"]) == sorted(t["score"] for t in plain["targets"]), fmt
    for fmt in ("gprmax", "forward", "synthetic", "packed"):
        sim = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": fmt})
        assert det.detect(sim, score_threshold=0.0)["refine"]["quality_weight"] == 1.0, fmt
    det.refiner.quality_weight = 2.0  # told: every record alike
    got = det.detect(Survey(data=s.data, dt_s=s.dt_s, metadata={"format": "dzt"}), score_threshold=0.0)
    assert got["refine"]["quality_weight"] == 2.0
    assert sorted(t["score"] for t in got["targets"]) == pytest.approx([0.075, 0.225])


def test_refiner_files_say_which_heads_they_have_and_a_rule_they_lack_is_one_line(tmp_path):
    p = tmp_path / "two.pt"
    net = R.build_refiner(2, True)
    assert net[-1].out_features == 10
    R.save_refiner(net, p, provenance={"name": "t", "rules": ["gpr3d", "pgpr"], "quality": True})
    ref = R.load_refiner(p, rule="pgpr", quality_weight=0.5)
    assert (ref.rules, ref.quality, ref.rule, ref.quality_weight) == (("gpr3d", "pgpr"), True, "pgpr", 0.5)
    assert ref.predict_crops(np.zeros((3, 3, R.CROP, R.CROP), np.float32)).shape == (3, 10)
    one = tmp_path / "one.pt"
    R.save_refiner(R.build_refiner(), one, provenance={"name": "one"})
    assert (R.load_refiner(one).rules, R.load_refiner(one).quality) == ((), False)
    with pytest.raises(InvalidDataError, match="^box rule pgpr: this refiner has one head"):
        R.load_refiner(one, rule="pgpr")
    for bad, msg in [(dict(rule="yolo"), "box rule must be auto or one of gpr3d, pgpr, got 'yolo'"),
                     (dict(quality_weight=-0.5), "the quality weight must be a number in 0..8, got -0.5"),
                     (dict(quality_weight=float("nan")), "the quality weight must be a number in 0..8, got nan"),
                     (dict(quality_weight=True), "the quality weight must be a number in 0..8, got True")]:
        with pytest.raises(InvalidDataError, match="^" + msg.replace(".", r"\.") + "$"):
            R.load_refiner(tmp_path / "never_read.pt", **bad)
    odd = tmp_path / "odd.pt"
    R.save_refiner(net, odd, provenance={"rules": ["gpr3d", "voc"], "quality": True})
    with pytest.raises(FormatError, match="label rules"):
        R.load_refiner(odd)
    for bad in ({"pgpr": -1}, {"voc": 1.0}, [1.0], {"pgpr": "1"}):
        R.save_refiner(net, odd, provenance={"rules": ["gpr3d", "pgpr"], "quality": True, "quality_weights": bad})
        with pytest.raises(FormatError, match="quality weights are"):
            R.load_refiner(odd)
    # the weight a refiner gives each rule, unless told one; 1 for a rule it gives none
    own = tmp_path / "own.pt"
    R.save_refiner(net, own, provenance={"rules": ["gpr3d", "pgpr"], "quality": True, "quality_weights": {"pgpr": 0}})
    picture, recording = Survey(data=np.zeros((4, 8)), dt_s=1e-10, metadata={"format": "picture"}), _survey()
    ref = R.load_refiner(own)
    assert (ref.weight_for(picture), ref.weight_for(recording)) == (0.0, 1.0)
    ref = R.load_refiner(own, quality_weight=2)
    assert (ref.weight_for(picture), ref.weight_for(recording)) == (2.0, 2.0)
    assert R.load_refiner(one).weight_for(recording) is None  # no quality head
    lying = tmp_path / "lying.pt"  # two heads with quality written, one head's provenance
    R.save_refiner(net, lying, provenance={"name": "lying"})
    with pytest.raises(FormatError, match="weights do not fit the refiner"):
        R.load_refiner(lying)


def test_an_onnx_export_of_two_heads_with_quality_gives_pytorch_s_outputs(tmp_path):
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    p = tmp_path / "two.pt"
    R.save_refiner(R.build_refiner(2, True), p, provenance={"name": "t", "rules": ["gpr3d", "pgpr"], "quality": True})
    r = R.export_refiner_onnx(p, tmp_path / "two.onnx")
    assert r["max_abs_diff"] < 1e-3
    o, t = R.load_refiner(tmp_path / "two.onnx", rule="pgpr"), R.load_refiner(p)
    assert (o.rules, o.quality, o.rule) == (("gpr3d", "pgpr"), True, "pgpr")
    crops = np.random.default_rng(0).random((4, 3, R.CROP, R.CROP), dtype=np.float32)
    np.testing.assert_allclose(o.predict_crops(crops), t.predict_crops(crops), atol=1e-3)


def _two_rule_records(n, rng, rows=64, cols=160):
    """Bars as in ``_blob_records``, each labelled by two rules: head 0 the bar grown 3 px sideways and 6 down,
    head 1 the bar itself."""
    out = []
    for img, label in _blob_records(n, rng, rows, cols):
        out.append((img, label, None, 0))
        bar = label + np.array([[3.0, 0.0, -3.0, -6.0]])
        out.append((img, bar, None, 1))
    return out


def test_two_heads_learn_their_own_rules_and_the_quality_head_ranks_boxes_by_their_iou():
    from scipy.stats import spearmanr

    rng = np.random.default_rng(0)
    net = R.train_refiner(_two_rule_records(30, rng), epochs=5, per_label=8, batch=64, heads=2, quality=4)
    assert net[-1].out_features == 10
    ref = R.BoxRefiner(net, {"rules": ["gpr3d", "pgpr"], "quality": True})
    moved_iou = {(h, rule): [] for h in (0, 1) for rule in (0, 1)}
    start_iou, q, true = [], [], []
    test = np.random.default_rng(5)
    for img, label in _blob_records(20, np.random.default_rng(1)):
        bar = label + np.array([[3.0, 0.0, -3.0, -6.0]])
        start = R.jitter_boxes(label, 4, test)
        out = ref.predict(img[None], start.astype(np.float32))
        for h in (0, 1):
            for rule, want in ((0, label), (1, bar)):
                moved_iou[h, rule].append(_iou(R.apply_deltas(start, out[:, 5 * h : 5 * h + 4]), np.repeat(want, 4, 0)))
        start_iou.append(_iou(start, np.repeat(label, 4, 0)))
        anywhere = np.concatenate([start, R.jitter_boxes(label, 4, test, R.WIDE_JITTER)])
        o = ref.predict(img[None], anywhere.astype(np.float32))
        q.append(o[:, 4])
        true.append(R.best_iou(anywhere, label))
    # each head moves the boxes onto its own rule (head 0 the grown box, head 1 the bar), not the other's
    m = {k: np.concatenate(v).mean() for k, v in moved_iou.items()}
    assert m[0, 0] > np.concatenate(start_iou).mean() + 0.1, m
    assert m[0, 0] > m[1, 0] + 0.1 and m[1, 1] > m[0, 1] + 0.1, m
    rho = spearmanr(np.concatenate(q), np.concatenate(true)).statistic
    assert rho > 0.8, rho  # (0.93 measured; the two heads' boxes 0.87 / 0.67 on their rules, 0.58 / 0.46 crossed)


def test_random_boxes_take_a_label_s_size_times_a_log_normal_factor_anywhere_in_the_picture():
    labels = np.array([[5.0, 10.0, 45.0, 20.0], [60.0, 0.0, 70.0, 30.0]])  # 40 x 10 and 10 x 30 (x1 - y0 != w)
    got = R._random_boxes(labels, 6000, 200, 100, np.random.default_rng(0))
    w, h = got[:, 2] - got[:, 0], got[:, 3] - got[:, 1]
    assert got.shape == (6000, 4) and (got[:, :2] >= 0).all() and (got[:, 2] <= 200).all() and (got[:, 3] <= 100).all()
    # each box's shape is one label's (its sides' ratio that label's times two independent factors): about half
    # each, told apart by the ratio against the midpoint of the labels' in log (2.2 spreads from either)
    wide = np.log(w / h) > 0.5 * (np.log(4.0) + np.log(1 / 3))
    assert 0.45 < wide.mean() < 0.55
    for sel, (w0, h0) in ((wide, (40.0, 10.0)), (~wide, (10.0, 30.0))):
        lw, lh = np.log(w[sel] / w0), np.log(h[sel] / h0)
        # median factor 1 and a spread of 0.4 in log, the two sides drawn apart (the two groups overlap a little
        # in the ratio, so the spread is measured between the quartiles)
        assert abs(np.median(lw)) < 0.05 and abs(np.median(lh)) < 0.05, (np.median(lw), np.median(lh))
        for v in (lw, lh):
            iqr = np.subtract(*np.percentile(v, [75, 25])) / 1.349
            assert 0.33 < iqr < 0.45, iqr
        assert abs(np.corrcoef(lw, lh)[0, 1]) < 0.2
    # placed anywhere the box fits: its left edge uniform over 0..cols - w
    u = got[:, 0] / (200 - w)
    assert 0 <= u.min() and u.max() <= 1 and abs(u.mean() - 0.5) < 0.02 and abs(np.std(u) - 12 ** -0.5) < 0.02
    v = got[:, 1] / (100 - h)
    assert abs(v.mean() - 0.5) < 0.02
    # a label wider and taller than the picture: the box is the picture less a pixel
    big = R._random_boxes(np.array([[0.0, 0.0, 900.0, 500.0]]), 50, 200, 100, np.random.default_rng(1))
    assert np.allclose(big[:, 2] - big[:, 0], 199.0) and np.allclose(big[:, 3] - big[:, 1], 99.0)
    assert (big[:, 0] >= 0).all() and (big[:, 0] <= 1).all()


def test_refiner_provenance_that_is_not_a_refiner_s_is_named_in_one_whole_line():
    with pytest.raises(FormatError) as e:
        R._heads({"rules": ["gpr3d", "voc"]}, "/x/r.pt")
    assert str(e.value) == "r.pt: a refiner whose heads follow the label rules ['gpr3d', 'voc']; this gpr3d knows " \
                           "gpr3d, pgpr"
    for rules in (["pgpr", "pgpr"], "gpr3d", ["gpr3d", 3]):  # twice one rule, not a list, not a name
        with pytest.raises(FormatError, match="label rules"):
            R._heads({"rules": rules}, "r.pt")
    with pytest.raises(FormatError) as e:
        R._heads({"rules": ["pgpr"], "quality": 1}, "/x/r.onnx")
    assert str(e.value) == "r.onnx: a refiner whose quality setting is 1, not true or false"
    with pytest.raises(FormatError) as e:
        R._heads({"quality": True, "quality_weights": {"pgpr": 9}}, "r.pt")
    assert str(e.value) == "r.pt: a refiner whose quality weights are {'pgpr': 9}: a rule's weight is a number in 0..8"
    assert R._heads({}, "r.pt") == ((), False)
    assert R._heads({"rules": ["pgpr", "gpr3d"], "quality": True, "quality_weights": {"gpr3d": 0, "pgpr": 8}},
                    "r.pt") == (("pgpr", "gpr3d"), True)
    assert R._heads({"rules": None, "quality": False, "quality_weights": {}}, "r.pt") == ((), False)


class _Heads:
    """Only what :meth:`BoxRefiner.head_for` reads."""

    head_for = R.BoxRefiner.head_for

    def __init__(self, rules, rule="auto"):
        self.rules, self.rule = tuple(rules), rule


def test_the_head_for_a_record_follows_its_kind_then_gpr3d_s_then_the_first():
    picture = Survey(data=np.zeros((4, 8)), dt_s=1e-10, metadata={"format": "picture"})
    recording, bare = _survey(), Survey(data=np.zeros((4, 8)), dt_s=1e-10)
    assert _Heads(["gpr3d", "pgpr"]).head_for(picture) == (1, "pgpr")
    assert _Heads(["gpr3d", "pgpr"]).head_for(recording) == (0, "gpr3d")
    assert _Heads(["pgpr", "gpr3d"]).head_for(recording) == (1, "gpr3d")  # gpr3d's wherever it stands
    assert _Heads(["pgpr", "gpr3d"]).head_for(bare) == (1, "gpr3d")  # no format: a recording
    assert _Heads(["pgpr"]).head_for(recording) == (0, "pgpr")  # no gpr3d head: the first
    assert _Heads(["gpr3d"]).head_for(picture) == (0, "gpr3d")  # no P-GPR head: gpr3d's
    assert _Heads(["gpr3d", "pgpr"]).head_for(None) == (0, "gpr3d")  # (no survey at all: a recording)
    assert _Heads(["gpr3d", "pgpr"], "pgpr").head_for(recording) == (1, "pgpr")
    assert _Heads([]).head_for(picture) == (0, None)
    with pytest.raises(InvalidDataError) as e:
        _Heads(["pgpr"], "gpr3d").head_for(recording)
    assert str(e.value) == "box rule gpr3d: this refiner's heads follow pgpr"
    with pytest.raises(InvalidDataError) as e:
        _Heads(["gpr3d", "pgpr"][:1], "pgpr").head_for(picture)
    assert str(e.value) == "box rule pgpr: this refiner's heads follow gpr3d"
    with pytest.raises(InvalidDataError) as e:
        _Heads([], "gpr3d").head_for(recording)
    assert str(e.value) == "box rule gpr3d: this refiner has one head (no rules to choose from)"


def test_quality_of_looks_at_the_boxes_where_they_are_with_the_record_s_head_and_both_looks():
    s = _survey()
    rows = 256
    image = np.zeros((3, rows, s.n_traces), np.float32)
    image[:, :, :150] = 1.0
    box = np.array([[120.0, 2e-9, 160.0, 4e-9]])
    ref = _TwoRules()
    ref.quality_of = R.BoxRefiner.quality_of.__get__(ref)
    crop = R.crop_array(image, np.array([R.record_pixmap(s, rows).box_to_px(b) for b in box]))
    a = 4.0 * (crop[0, 0, :, : R.CROP // 2].mean() - crop[0, 0, :, R.CROP // 2 :].mean())
    # a recording: gpr3d's head, the box not moved first
    np.testing.assert_allclose(ref.quality_of(s, rows, box, image), [1 / (1 + np.exp(-a))], rtol=1e-5)
    picture = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": "picture"})
    # P-GPR's head: its logit one more than gpr3d's
    np.testing.assert_allclose(ref.quality_of(picture, rows, box, image), [1 / (1 + np.exp(-a - 1))], rtol=1e-5)
    ref.mirror = True  # the mirrored look's logit is -a: the two looks' mean
    want = 0.5 * (1 / (1 + np.exp(-a - 1)) + 1 / (1 + np.exp(a - 1)))
    np.testing.assert_allclose(ref.quality_of(picture, rows, box, image), [want], rtol=1e-5)
    ref.quality = False
    with pytest.raises(InvalidDataError, match="^two rules has no quality head$"):
        ref.quality_of(s, rows, box, image)
    ref.provenance = {}
    with pytest.raises(InvalidDataError) as e:
        ref.quality_of(s, rows, box, image)
    assert str(e.value) == "this refiner has no quality head"


def test_no_boxes_give_no_boxes_and_a_quality_only_where_one_is_asked_for():
    s = _survey()
    image = np.zeros((3, 256, s.n_traces), np.float32)

    def never(crops):
        raise AssertionError("no crops to look at")

    b, q = R._refined(s, 256, [], image, never, mirror=True, passes=2)  # by default neither quality nor score
    assert b.shape == (0, 4) and q is None
    for quality, score in ((True, False), (False, True)):
        assert R._refined(s, 256, np.zeros((0, 4)), image, never, mirror=False, passes=1, quality=quality,
                          score=score)[1] is None
    b, q = R._refined(s, 256, np.zeros((0, 4)), image, never, mirror=False, passes=1, quality=True, score=True)
    assert b.shape == (0, 4) and isinstance(q, np.ndarray) and q.shape == (0,)
    # with boxes: a quality only with both asked (a network of one head with quality: its fifth column)
    box = np.array([[120.0, 2e-9, 160.0, 4e-9]])

    def fifth(crops):
        return np.tile([0.0, 0.0, 0.0, 0.0, 2.0], (len(crops), 1))

    assert R._refined(s, 256, box, image, fifth, mirror=False, passes=1, quality=True)[1] is None
    np.testing.assert_allclose(R._refined(s, 256, box, image, fifth, mirror=False, passes=1, quality=True,
                                          score=True)[1], [1 / (1 + np.exp(-2.0))])
    ref = _TwoRules()  # refine asks for no quality: no last look
    looks = []
    ref.predict_crops = lambda c: looks.append(len(c)) or _TwoRules.predict_crops(ref, c)
    ref.refine(s, 256, box, image)
    assert looks == [1]  # one pass, no last look


def test_refiner_files_name_themselves_in_what_is_wrong_with_their_heads(tmp_path):
    net = R.build_refiner(2, True)
    with pytest.raises(FormatError) as e:
        R.BoxRefiner(net, {"rules": ["gpr3d", "voc"]})
    assert str(e.value).startswith("refiner: a refiner whose heads follow the label rules ['gpr3d', 'voc']")
    with pytest.raises(FormatError) as e:
        R.OnnxBoxRefiner(None, {"quality": "yes"})
    assert str(e.value) == "refiner graph: a refiner whose quality setting is 'yes', not true or false"
    odd = tmp_path / "odd.pt"
    R.save_refiner(net, odd, provenance={"rules": ["gpr3d", "voc"], "quality": True})
    with pytest.raises(FormatError) as e:
        R.load_refiner(odd)
    assert str(e.value) == "odd.pt: a refiner whose heads follow the label rules ['gpr3d', 'voc']; this gpr3d " \
                           "knows gpr3d, pgpr"
    two = tmp_path / "two.pt"
    R.save_refiner(net, two, provenance={"rules": ["pgpr", "gpr3d"], "quality": True})
    assert R.load_refiner(two, rule="gpr3d").head_for(None) == (1, "gpr3d")  # a rule it has: its head
    one = tmp_path / "one.pt"
    R.save_refiner(R.build_refiner(1, True), one, provenance={"rules": ["pgpr"], "quality": True})
    with pytest.raises(InvalidDataError) as e:
        R.load_refiner(one, rule="gpr3d")
    assert str(e.value) == "box rule gpr3d: this refiner's heads follow pgpr"


def test_an_onnx_refiner_whose_outputs_do_not_fit_its_provenance_is_one_line(tmp_path):
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    import onnx

    from gpr3d.io.onnxweights import finish_export

    R.save_refiner(R.build_refiner(2, True), tmp_path / "two.pt",
                   provenance={"name": "t", "rules": ["gpr3d", "pgpr"], "quality": True})
    R.export_refiner_onnx(tmp_path / "two.pt", tmp_path / "two.onnx")
    g = onnx.load(str(tmp_path / "two.onnx"))
    meta = __import__("json").loads({p.key: p.value for p in g.metadata_props}["gpr3d.refiner"])
    for name, prov, says in [("one.onnx", {"name": "t"}, "1 head(s)"),
                             ("q.onnx", {"name": "t", "rules": ["gpr3d"], "quality": True}, "1 head(s) with quality"),
                             ("r.onnx", {"name": "t", "rules": ["gpr3d", "pgpr"]}, "2 head(s)")]:
        onnx.save(g, str(tmp_path / name))
        finish_export(tmp_path / name, "gpr3d.refiner", dict(meta, provenance=prov))
        with pytest.raises(FormatError) as e:
            R.load_refiner(tmp_path / name)
        assert str(e.value) == f"{name}: a refiner graph of 10 outputs a box where its provenance says {says}"


def test_quality_training_draws_wide_and_anywhere_boxes_and_checks_its_heads(monkeypatch):
    """With ``quality`` k: per label k boxes drawn about it with :data:`WIDE_JITTER` and k anywhere in the picture
    (``_random_boxes``), their targets the IoU with the nearest label; a sample's head must be one the refiner has;
    the quality's loss weighs 0.2 unless told (the shipped recipe)."""
    import inspect

    spreads, anywhere = [], []
    real_jitter, real_random = R.jitter_boxes, R._random_boxes

    def spy_jitter(boxes, n, rng, spread=None):
        spreads.append((n, spread))
        return real_jitter(boxes, n, rng, spread)

    def spy_random(labels, n, cols, rows, rng):
        anywhere.append((n, cols, rows))
        return real_random(labels, n, cols, rows, rng)

    monkeypatch.setattr(R, "jitter_boxes", spy_jitter)
    monkeypatch.setattr(R, "_random_boxes", spy_random)
    img = np.random.default_rng(0).random((3, 40, 90), dtype=np.float32)
    labels = np.array([[10.0, 8.0, 30.0, 20.0], [50.0, 5.0, 80.0, 30.0]])
    net = R.train_refiner([(img, labels, None, 1)], epochs=1, per_label=3, batch=64, heads=2, quality=5)
    assert net[-1].out_features == 10
    assert spreads == [(3, R.JITTER), (5, R.WIDE_JITTER)] and anywhere == [(10, 90, 40)]
    assert inspect.signature(R.train_refiner).parameters["quality_loss"].default == 0.2
    spreads.clear()  # a fine stage: the boxes about the labels drawn closer by the scale, the wide ones as they were
    R.train_refiner([(img, labels, None, 1)], epochs=1, per_label=3, batch=64, heads=2, quality=5, jitter_scale=0.5)
    assert spreads == [(3, {"centre": 0.03, "width": 0.1, "top": 0.05, "bottom": 0.075}), (5, R.WIDE_JITTER)]
    built = []
    real_build = R.build_refiner

    def spy_build(*a, **k):
        built.append(k.get("seed"))
        return real_build(*a, **k)

    monkeypatch.setattr(R, "build_refiner", spy_build)
    spreads.clear()  # the largest scale allowed; the network drawn from the training's seed
    R.train_refiner([(img, labels)], epochs=1, per_label=2, batch=64, jitter_scale=4.0, seed=7)
    assert spreads == [(2, {k: 4.0 * v for k, v in R.JITTER.items()})] and built == [7]
    for bad in (0, -0.5, 4.5, True, "0.5", float("nan")):
        with pytest.raises(InvalidDataError) as e:
            R.train_refiner([(img, labels)], jitter_scale=bad)
        assert str(e.value) == f"the jitter scale must be a number in (0, 4], got {bad!r}"
    with pytest.raises(InvalidDataError) as e:
        R.train_refiner([(img, labels, None, 2)], epochs=1, heads=2)
    assert str(e.value) == "a sample names head 2, the refiner has 2"
    with pytest.raises(InvalidDataError, match="^epochs, per_label, batch and heads must be positive and quality not "
                                               "negative, got 9, 24, 128, 1, -1$"):
        R.train_refiner([], quality=-1)
    with pytest.raises(InvalidDataError, match="got 9, 24, 128, 0, 0$"):
        R.train_refiner([], heads=0)


def test_the_export_reports_how_far_the_graph_s_qualities_are_from_pytorch_s(tmp_path, monkeypatch):
    """PyTorch's quality logits made one more than the graph's (a known gap): the export reports the largest gap of
    the predicted IoUs, sigmoid(x + 1) - sigmoid(x), which for a fresh network's small logits lies just under its
    ceiling of 0.245 (at x = -0.5); the edge moves are untouched."""
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    p = tmp_path / "two.pt"
    R.save_refiner(R.build_refiner(2, True), p, provenance={"name": "t", "rules": ["gpr3d", "pgpr"], "quality": True})
    real = R.BoxRefiner.predict_crops

    def shifted(self, crops_):
        out = real(self, crops_)
        out[:, [4, 9]] += 1.0
        return out

    monkeypatch.setattr(R.BoxRefiner, "predict_crops", shifted)
    r = R.export_refiner_onnx(p, tmp_path / "two.onnx")
    assert r["max_abs_diff"] < 1e-3
    # (the ceiling plus 1e-3: the graph's float32 logits may differ from PyTorch's by rounding, which moves a
    # sigmoid by at most a quarter of it; the mutants this guards against move the gap by 0.05 or more)
    assert 0.2 < r["max_quality_diff"] <= 1 / (1 + np.exp(-0.5)) - 1 / (1 + np.exp(0.5)) + 1e-3, r


def test_a_quality_weight_of_8_is_the_largest_allowed():
    assert R.check_quality_weight(8) == 8.0 and R.check_quality_weight(np.float32(0.0)) == 0.0
    assert R.check_quality_weight(None) is None
    for bad in (8.001, 9, -1e-9):
        with pytest.raises(InvalidDataError, match=f"^the quality weight must be a number in 0..8, got {bad!r}$"):
            R.check_quality_weight(bad)


class _Stage:
    """A fine stage whose network asks fixed edge moves of every crop, per head: ``moves`` (heads, 4)."""

    quality, whole = False, False

    def __init__(self, moves, rules=(), name="fixed fine stage"):
        self.moves, self.rules, self.seen = np.asarray(moves, float).reshape(-1, 4), tuple(rules), []
        self.provenance = {"name": name}

    def predict_crops(self, crops):
        self.seen.append(crops.copy())
        return np.repeat(self.moves.reshape(1, -1), len(crops), 0)


def test_a_fine_stage_moves_each_box_once_more_after_the_passes_from_where_they_ended():
    s = _survey()
    rows = 256
    image = _coordinates(rows, s.n_traces)
    boxes = np.array([[70.0, 3e-9, 110.0, 4e-9], [150.0, 2.5e-9, 190.0, 3.5e-9]])
    first, fine = _Fixed([0.1, 0.0, 0.1, 0.0]), _Stage([0.0, -0.25, 0.0, 0.5])
    first.passes = 2
    first.fine = fine
    got = first.refine(s, rows, boxes, image)
    pm = R.record_pixmap(s, rows)
    px = np.array([pm.box_to_px(b) for b in boxes])
    after = R.apply_deltas(R.apply_deltas(px, [[0.1, 0.0, 0.1, 0.0]] * 2), [[0.1, 0.0, 0.1, 0.0]] * 2)
    want = R.apply_deltas(after, [[0.0, -0.25, 0.0, 0.5]] * 2)
    np.testing.assert_allclose(got, [pm.px_to_box(b) for b in want], rtol=1e-9)
    assert len(first.seen) == 2 and len(fine.seen) == 1  # two passes, then the fine stage once
    np.testing.assert_allclose([_box_of(c) for c in fine.seen[0]], after, rtol=1e-5)  # cut where the passes ended
    first.fine = None  # without it: the passes' boxes
    np.testing.assert_allclose(first.refine(s, rows, boxes, image), [pm.px_to_box(b) for b in after], rtol=1e-9)


def _dark_record_two_rules():
    """A record, its rows, a black picture of it, one box 40 traces wide at trace 120 and a :class:`_TwoRules`
    refiner whose quality does not weigh the scores: ``(survey, rows, image, box, refiner)``."""
    s = _survey()
    ref = _TwoRules()
    ref.quality_weight = None
    return s, 256, np.zeros((3, 256, s.n_traces), np.float32), np.array([[120.0, 2e-9, 160.0, 4e-9]]), ref


def test_a_fine_stage_sees_each_box_mirrored_too_and_takes_the_head_of_the_first_refiner_s_rule():
    s, rows, image, box, ref = _dark_record_two_rules()
    ref.fine = _Stage([[0.0, 0.0, 0.3, 0.0], [0.2, 0.0, 0.0, 0.0]], rules=("gpr3d", "pgpr"))
    moved, _ = ref.refine_scored(s, rows, box, image)  # gpr3d's head: 124 -> right edge + 0.3 x 36
    np.testing.assert_allclose(moved[0, [0, 2]], [124.0, 160.0 + 0.3 * 36.0], rtol=1e-9)
    picture = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": "picture"})
    moved_p, _ = ref.refine_scored(picture, rows, box, image)  # P-GPR's head: 116 -> left edge + 0.2 x 44
    np.testing.assert_allclose(moved_p[0, [0, 2]], [116.0 + 0.2 * 44.0, 160.0], rtol=1e-9)
    ref.mirror = True  # each look averaged with the mirror's: the first refiner's left move halves, so does the fine's
    both, _ = ref.refine_scored(picture, rows, box, image)
    # the first look: left edge 0.05 x 40 out, the right edge as much (the mirror's left move): 118..162, 44 wide
    np.testing.assert_allclose(both[0, [0, 2]], [118.0 + 0.5 * 0.2 * 44, 162.0 - 0.5 * 0.2 * 44], rtol=1e-9)
    assert len(ref.fine.seen[-1]) == 2  # both looks in one batch


def test_the_quality_is_read_where_the_fine_stage_left_each_box():
    s, rows, image, box, _ = _dark_record_two_rules()
    image[:, :, :150] = 1.0  # the left half of the record bright
    ref = _TwoRules()  # (its own quality weight)
    ref.fine = _Stage([[0.5, 0.0, 0.5, 0.0], [0.0, 0.0, 0.0, 0.0]], rules=("gpr3d", "pgpr"))
    moved, q = ref.refine_scored(s, rows, box, image)
    np.testing.assert_allclose(moved[0, [0, 2]], [124.0 + 18.0, 160.0 + 18.0], rtol=1e-9)
    crop = R.crop_array(image, np.array([R.record_pixmap(s, rows).box_to_px(b) for b in moved]))
    a = 4.0 * (crop[0, 0, :, : R.CROP // 2].mean() - crop[0, 0, :, R.CROP // 2 :].mean())
    np.testing.assert_allclose(q, [1 / (1 + np.exp(-a))], rtol=1e-5)


def test_a_fine_stage_must_fit_the_refiner_it_follows():
    ref = R.BoxRefiner(R.build_refiner(2, True), {"name": "first", "rules": ["gpr3d", "pgpr"], "quality": True,
                                                   "whole": True})
    ok = R.BoxRefiner(R.build_refiner(2), {"name": "fine", "rules": ["gpr3d", "pgpr"], "whole": True})
    assert ref.with_fine(ok) is ref and ref.fine is ok
    assert ref.with_fine(None).fine is None
    one = R.BoxRefiner(R.build_refiner(1), {"name": "one head", "whole": True})
    with pytest.raises(InvalidDataError, match="^one head: a fine stage whose heads follow one rule, the refiner's "
                                               "gpr3d, pgpr$"):
        ref.with_fine(one)
    q = R.BoxRefiner(R.build_refiner(2, True), {"name": "q", "rules": ["gpr3d", "pgpr"], "quality": True,
                                                 "whole": True})
    with pytest.raises(InvalidDataError, match=r"^q: a fine stage with a quality head \(the first refiner's is used\)$"):
        ref.with_fine(q)
    part = R.BoxRefiner(R.build_refiner(2), {"name": "cut", "rules": ["gpr3d", "pgpr"]})
    with pytest.raises(InvalidDataError, match="^cut: a fine stage not trained on whole hyperbolas' boxes, the "
                                               "refiner so$"):
        ref.with_fine(part)
    assert ref.fine is None  # a refused stage is not taken
    both = R.BoxRefiner(R.build_refiner(2), {"rules": ["gpr3d", "pgpr"], "whole": True})  # (it names itself not)
    with pytest.raises(InvalidDataError, match="^the fine stage: a fine stage whose heads follow gpr3d, pgpr, the "
                                               "refiner's one rule$"):
        R.BoxRefiner(R.build_refiner(1), {"name": "one", "whole": True}).with_fine(both)
    whole = R.BoxRefiner(R.build_refiner(1), {"name": "whole", "whole": True})
    with pytest.raises(InvalidDataError, match="^whole: a fine stage trained on whole hyperbolas' boxes, the refiner "
                                               "not so$"):
        R.BoxRefiner(R.build_refiner(1), {"name": "cut"}).with_fine(whole)
    pictures = R.BoxRefiner(R.build_refiner(1), {"name": "pictures", "rules": ["pgpr"]})
    assert ref.with_fine(pictures).fine is pictures  # P-GPR's rule alone: its pictures name no apexes, none is whole
    lone = R.BoxRefiner(R.build_refiner(1), {"name": "lone"})
    with pytest.raises(InvalidDataError, match="^lone: a fine stage not trained on whole hyperbolas' boxes, the "
                                               "refiner so$"):
        R.BoxRefiner(R.build_refiner(1), {"name": "one", "whole": True}).with_fine(lone)


def test_load_refiner_takes_a_fine_stage_from_a_file_and_none_from_auto_with_another_refiner(tmp_path):
    first, fine = tmp_path / "first.pt", tmp_path / "fine.pt"
    R.save_refiner(R.build_refiner(), first, provenance={"name": "first"})
    R.save_refiner(R.build_refiner(), fine, provenance={"name": "fine", "jitter_scale": 0.5})
    assert R.load_refiner(first).fine is None  # auto: another refiner comes without the shipped fine stage
    assert R.load_refiner(first, fine="none").fine is None
    got = R.load_refiner(first, fine=fine)
    assert got.fine.provenance["name"] == "fine"
    x = np.random.default_rng(0).normal(size=(3, 3, R.CROP, R.CROP)).astype(np.float32)
    np.testing.assert_array_equal(got.fine.predict_crops(x), R.BoxRefiner.load(fine).predict_crops(x))
    with pytest.raises(InvalidDataError, match="^the fine stage must be auto, none, default or a refiner's file, "
                                               "got 3$"):
        R.load_refiner(first, fine=3)
    with pytest.raises(FormatError, match="no such box refiner weights file"):
        R.load_refiner(first, fine=tmp_path / "missing.pt")


def test_a_refiner_of_several_members_averages_their_outputs_and_its_file_says_how_many(tmp_path):
    net = R.build_refiner(2, False, members=3, seed=5)
    x = torch.from_numpy(np.random.default_rng(1).normal(size=(4, 3, R.CROP, R.CROP)).astype(np.float32))
    net.eval()
    with torch.inference_mode():
        each = [m(x).numpy() for m in net.members]
        np.testing.assert_allclose(net(x).numpy(), np.mean(each, axis=0), rtol=1e-5, atol=1e-7)
        # member k is drawn from seed + k: the first is the one network of seed 5, the second that of seed 6
        np.testing.assert_array_equal(each[1], R.build_refiner(2, seed=6).eval()(x).numpy())
    assert not np.allclose(each[0], each[1])
    path = tmp_path / "three.pt"
    R.save_refiner(net, path, provenance={"name": "three", "rules": ["gpr3d", "pgpr"], "members": 3})
    back = R.load_refiner(path)
    np.testing.assert_allclose(back.predict_crops(x.numpy()), net(x).detach().numpy(), rtol=2e-2, atol=2e-3)  # float16
    graph = R.export_refiner_onnx(path, tmp_path / "three.onnx")
    assert graph["max_abs_diff"] < 1e-4
    np.testing.assert_allclose(R.load_refiner(tmp_path / "three.onnx").predict_crops(x.numpy()),
                               back.predict_crops(x.numpy()), rtol=1e-4, atol=1e-5)
    R.save_refiner(net, tmp_path / "said_one.pt", provenance={"name": "three", "rules": ["gpr3d", "pgpr"]})
    with pytest.raises(FormatError, match="said_one.pt: weights do not fit the refiner"):
        R.load_refiner(tmp_path / "said_one.pt")
    for bad in (0, 1.5, True, "3"):
        R.save_refiner(net, tmp_path / "bad.pt", provenance={"members": bad})
        with pytest.raises(FormatError) as e:
            R.load_refiner(tmp_path / "bad.pt")
        assert str(e.value) == f"bad.pt: a refiner of {bad!r} members; a whole number >= 1 was expected"
    for bad in (0, -1, 2.0, True):
        with pytest.raises(InvalidDataError, match=f"^a refiner's members must be a whole number >= 1, got {bad!r}$"):
            R.build_refiner(members=bad)


def test_a_fine_stage_of_some_rules_moves_only_their_boxes():
    s, rows, image, box, ref = _dark_record_two_rules()
    R.BoxRefiner.with_fine(ref, _Stage([0.2, 0.0, 0.0, 0.0], rules=("pgpr",)))
    picture = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": "picture"})
    np.testing.assert_allclose(ref.refine(picture, rows, box, image)[0, [0, 2]], [116.0 + 0.2 * 44.0, 160.0],
                               rtol=1e-9)  # P-GPR's rule: moved once more
    assert ref.fine_for(picture)[1] == 0 and ref.fine_for(s) is None
    np.testing.assert_allclose(ref.refine(s, rows, box, image)[0, [0, 2]], [124.0, 160.0], rtol=1e-9)  # gpr3d's: not


def test_the_detector_names_the_fine_stage_that_moved_its_boxes():
    from gpr3d.detection.windows import WindowConfig

    s = _survey(n_traces=256)
    det = _one_box_detector(WindowConfig(traces=256, rows=128, overlap=0.0))
    det.refiner = _Fixed([0.0, 0.0, 0.2, 0.0])
    first = det.detect(s)
    det.refiner.fine = _Stage([0.0, 0.0, 0.0, 0.1])
    both = det.detect(s)
    assert both["refine"] == {"mirror": False, "passes": 1, "fine": "fixed fine stage", "duplicate_iou": 0.5}
    a, b = np.asarray(first["targets"][0]["box"]), np.asarray(both["targets"][0]["box"])
    np.testing.assert_allclose(b[:3], a[:3])
    np.testing.assert_allclose(b[3] - a[3], 0.1 * (a[3] - a[1]), rtol=1e-6)  # the fine stage's move, after the first's
    det.refiner.fine = _Stage([0.0, 0.0, 0.0, 0.1], rules=("pgpr",))  # a stage of another rule than the record's
    det.refiner.rules, det.refiner.d = ("gpr3d", "pgpr"), np.tile(det.refiner.d, 2)  # two heads, moving alike
    det.refiner.fine.provenance = {}
    got = det.detect(s)
    assert got["refine"]["fine"] is None and got["refine"]["rule"] == "gpr3d"
    np.testing.assert_allclose(got["targets"][0]["box"], a)
    picture = Survey(data=s.data, dt_s=s.dt_s, metadata={"format": "picture"})
    assert det.detect(picture)["refine"]["fine"] == "fine stage"  # one that names itself not: so called
