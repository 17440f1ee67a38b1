"""DepthNet's pieces by hand: settings' messages in full, window columns and boxes from hand-computed cases, the
time crop, RoIs, the loss, record caching, the training loop (with a stand-in network: which windows each step
draws, exact resume, the log and checkpoint), and the estimator (with a stand-in ONNX session: which windows it is
asked for, and how eps_r, its uncertainty and the depths follow from the answers).
"""

import json
import math

import numpy as np
import pytest

from gpr3d import __version__
from gpr3d.core import training
from gpr3d.core.errors import FormatError, GPR3DError, InvalidDataError
from gpr3d.core.units import C0
from gpr3d.inversion import depthnet as dn
from gpr3d.inversion.depthnet import (
    DepthConfig,
    DepthEstimator,
    DepthRecord,
    DepthTrainConfig,
    box_to_window,
    crop_time,
    depth_window,
    window_targets_m,
)


def ramp_record(n=4, size=6, spacing=0.1, window_s=10e-9, labels=(), direct_frac=0.1, eps=6.0):
    """Trace i, row r holds (i + 1) * (r + 1); traces ``spacing`` apart from 0."""
    proc = (np.arange(1, n + 1)[:, None] * np.arange(1, size + 1)[None, :]).astype(np.float32)
    return DepthRecord(proc=proc, x_m=np.arange(n) * spacing, window_s=window_s, direct_frac=direct_frac, scale=2.0,
                       offset_m=0.05, dt_s=1e-11, eps_r=eps, labels=list(labels))


# ------------------------------------------------------------------------------------------------ settings

@pytest.mark.parametrize("kw, msg", [
    ({"arch": "vgg16"}, "unknown DepthNet encoder 'vgg16'; choose one of resnet10n, resnet18, resnet34, resnet50, "
                        "resnet101"),
    ({"width": 7}, "DepthNet width must be an integer in 8..128, got 7"),
    ({"width": 129}, "DepthNet width must be an integer in 8..128, got 129"),
    ({"width": 16.0}, "DepthNet width must be an integer in 8..128, got 16.0"),
    ({"size": 32}, "DepthNet window size must be a multiple of 32 in 64..1024, got 32"),
    ({"size": 1056}, "DepthNet window size must be a multiple of 32 in 64..1024, got 1056"),
    ({"size": 100}, "DepthNet window size must be a multiple of 32 in 64..1024, got 100"),
    ({"size": 224.0}, "DepthNet window size must be a multiple of 32 in 64..1024, got 224.0"),
    ({"alpha": 0.04}, "DepthNet alpha must lie in 0.05..5, got 0.04"),
    ({"alpha": 5.01}, "DepthNet alpha must lie in 0.05..5, got 5.01"),
])
def test_depth_config_names_each_wrong_value_in_full(kw, msg):
    with pytest.raises(InvalidDataError) as err:
        DepthConfig(**kw)
    assert str(err.value) == msg


def test_depth_config_defaults_and_edges():
    d = DepthConfig()
    assert (d.arch, d.width, d.size, d.alpha) == ("resnet10n", 24, 224, 0.5)
    for kw in ({"width": 8}, {"width": 128}, {"size": 64}, {"size": 1024}, {"alpha": 0.05}, {"alpha": 5.0},
               {"arch": "resnet101"}):
        DepthConfig(**kw)


@pytest.mark.parametrize("kw, msg", [
    ({"optimiser": "sgd"}, "unknown optimiser 'sgd'; choose one of adamw, reference"),
    ({"steps": 0}, "--steps must be an integer >= 1, got 0"),
    ({"batch": 1}, "--batch must be an integer >= 2, got 1"),
    ({"batch": 4.0}, "--batch must be an integer >= 2, got 4.0"),
    ({"checkpoint_every": 0}, "--checkpoint-every must be an integer >= 1, got 0"),
    ({"seed": -1}, "--seed must be an integer >= 0, got -1"),
    ({"lr": 0.0}, "--lr must lie in (0, 10), got 0.0"),
    ({"lr": 10}, "--lr must lie in (0, 10), got 10"),
    ({"lambda_eps": -0.5}, "--lambda-eps must be a number >= 0, got -0.5"),
    ({"lambda_eps": float("nan")}, "--lambda-eps must be a number >= 0, got nan"),
    ({"lambda_depth": float("inf")}, "--lambda-depth must be a number >= 0, got inf"),
    ({"lambda_depth": "1"}, "--lambda-depth must be a number >= 0, got '1'"),
    ({"net": {"width": 4}}, "DepthNet width must be an integer in 8..128, got 4"),
])
def test_train_config_names_each_wrong_value_in_full(kw, msg):
    with pytest.raises(InvalidDataError) as err:
        DepthTrainConfig(out="x", **kw)
    assert str(err.value) == msg


def test_train_config_defaults_and_edges():
    d = DepthTrainConfig(out="x")
    assert (d.steps, d.batch, d.lr, d.optimiser, d.lambda_eps, d.lambda_depth, d.seed, d.device,
            d.checkpoint_every, d.init) == (1500, 16, None, "adamw", 1.0, 1.0, 0, "cpu", 100, None)
    assert d.net == {"arch": "resnet10n", "width": 24, "size": 224, "alpha": 0.5}
    DepthTrainConfig(out="x", steps=1, batch=2, checkpoint_every=1, seed=0, lr=9.99, lambda_eps=0, lambda_depth=0.0)


# ------------------------------------------------------------------------------------------------ windows

def test_a_record_s_scales():
    rec = ramp_record(size=6, window_s=10e-9)
    assert rec.depth_scale_m == C0 * 10e-9 / 2
    assert rec.s_per_row == 10e-9 / 5
    np.testing.assert_allclose(rec.x_of_trace([0, 1.5, 3, 7]), [0.0, 0.15, 0.3, 0.3], rtol=0, atol=1e-15)


def test_window_columns_interpolate_the_traces_and_leave_zeros_beyond_them():
    """Columns at -0.07, 0.03, ..., 0.43 m over traces at 0, 0.1, 0.2, 0.3 m: the first lies more than half a
    spacing before the first trace (zero), 0.33 m within half a spacing after the last (its value), 0.43 m beyond."""
    rec = ramp_record()
    got = dn._columns(rec, -0.12, 0.6, 6, rec.proc)
    rows = np.arange(1, 7)
    want = np.array([0.0, 1.3, 2.3, 3.3, 4.0, 0.0])[:, None] * rows[None, :]
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    assert got.dtype == np.float32
    # a single trace: no spacing, so every column but the trace's own position is outside
    one = DepthRecord(proc=rec.proc[:1], x_m=np.array([0.0]), window_s=1e-8, direct_frac=0.1, scale=1.0)
    np.testing.assert_array_equal(dn._columns(one, -0.25, 0.5, 2, one.proc), 0.0)


def test_traces_are_box_filtered_where_several_share_a_column():
    rec = ramp_record(n=9, spacing=0.01)
    # columns 3 cm wide over traces 1 cm apart: a running mean of 3 traces (ends repeated)
    sm = dn._smoothed(rec, 0.18, 6)
    col = np.arange(1, 10, dtype=float)
    want = np.convolve(np.r_[col[0], col, col[-1]], np.ones(3) / 3, mode="valid")
    np.testing.assert_allclose(sm[:, 0], want, rtol=1e-6)
    np.testing.assert_allclose(sm[:, 2], 3 * want, rtol=1e-6)
    # 1.4 traces a column: left as they are (the same array)
    assert dn._smoothed(rec, 0.084, 6) is rec.proc
    assert dn._smoothed(rec, 0.096, 6) is not rec.proc  # 1.6 traces: rounded to a filter of 2
    np.testing.assert_allclose(dn._smoothed(rec, 0.096, 6)[1:, 0], 0.5 * (col[1:] + col[:-1]), rtol=1e-6)
    one = DepthRecord(proc=rec.proc[:1], x_m=np.array([0.0]), window_s=1e-8, direct_frac=0.1, scale=1.0)
    assert dn._smoothed(one, 1.0, 6) is one.proc



def test_a_cart_that_stood_still_is_filtered_by_its_mean_interval_never_wider_than_the_record():
    """Positions from a few GPS fixes (MALA's ten_col.rd3): seven traces at one place, then three 17 mm apart, so
    the median interval is nil (once: a 35-million-trace filter, 59 GiB). The mean interval is 51 mm / 9."""
    rec = ramp_record(n=10)
    rec.x_m = np.r_[np.zeros(7), 0.017, 0.034, 0.051] + np.arange(10) * 1e-9  # as prepare_depth_record makes them
    col = np.arange(1, 11, dtype=float)
    # columns 17 mm wide: 3 traces a column
    want = np.convolve(np.r_[col[0], col, col[-1]], np.ones(3) / 3, mode="valid")
    np.testing.assert_allclose(dn._smoothed(rec, 6 * 0.017, 6)[:, 0], want, rtol=1e-6)
    # where the record starts does not matter, only its length
    far = ramp_record(n=10)
    far.x_m = rec.x_m + 5.0
    np.testing.assert_array_equal(dn._smoothed(far, 6 * 0.017, 6), dn._smoothed(rec, 6 * 0.017, 6))
    # a column wider than the record: a centred filter of 11, the ends repeated
    wide = dn._smoothed(rec, 6.0, 6)[:, 0]
    padded = np.r_[np.full(5, col[0]), col, np.full(5, col[-1])]
    np.testing.assert_allclose(wide, [padded[i:i + 11].mean() for i in range(10)], rtol=1e-6)
    # half a mean interval either side of the traces still counts as inside
    got = dn._columns(rec, 0.051 + 0.5 * 0.051 / 9 - 0.002, 0.004, 1, rec.proc)
    np.testing.assert_allclose(got[0], rec.proc[-1], rtol=1e-6)
    assert not dn._columns(rec, 0.051 + 0.5 * 0.051 / 9 + 0.0005, 0.001, 1, rec.proc).any()

def test_a_window_is_centred_and_sized_to_alpha_times_the_vacuum_depth():
    rec = ramp_record(n=40, size=64, spacing=0.01, window_s=4e-9)
    cfg = DepthConfig(size=64, alpha=0.5)
    image, left, width = depth_window(rec, 0.2, cfg)
    assert width == pytest.approx(0.5 * C0 * 4e-9 / 2, rel=1e-12)
    assert left == pytest.approx(0.2 - width / 2, rel=1e-12)
    assert image.shape == (3, 64, 64) and image.dtype == np.float32
    from gpr3d.processing.image import render_channels

    want = render_channels(dn._columns(rec, left, width, 64, dn._smoothed(rec, width, 64)), "channels", scale=2.0)
    np.testing.assert_array_equal(image, want)
    given = np.zeros_like(rec.proc)
    np.testing.assert_array_equal(depth_window(rec, 0.2, cfg, smoothed=given)[0],
                                  render_channels(np.zeros((64, 64), np.float32), "channels", scale=2.0))


def test_a_box_in_window_pixels():
    rec = ramp_record(n=11, size=11, spacing=0.1, window_s=10e-9)  # 1 ns a row
    got = box_to_window(rec, [2, 3e-9, 4.5, 7e-9], 0.1, 0.8, 100)
    np.testing.assert_allclose(got, [12.5, 3.5, 43.75, 7.5], rtol=1e-12)


def test_window_targets_keep_apexes_inside_clip_boxes_and_give_depth_fractions():
    lab = lambda apex, box, depth: {"apex_trace": apex, "box": box, "depth_m": depth}  # noqa: E731
    labels = [lab(5, [3, 2e-9, 7, 6e-9], 0.3),          # inside
              lab(12, [11, 2e-9, 13, 6e-9], 0.2),       # apex right of the window (x 1.2 m)
              lab(1, [-2, 1e-9, 2, 150e-9], 0.6),       # apex inside, box clipped left and below
              lab(9, [8.995, 1e-9, 9.004, 4e-9], 0.1)]  # under a pixel wide
    rec = ramp_record(n=21, size=11, spacing=0.1, window_s=10e-9, labels=labels)
    boxes, q = window_targets_m(rec, 0.05, 1.0, 100)
    d = rec.depth_scale_m
    np.testing.assert_allclose(boxes, [[25, 2.5, 65, 6.5], [0, 1.5, 15, 100.0]], rtol=1e-6)
    np.testing.assert_allclose(q, [0.3 / d, 0.6 / d], rtol=1e-6)
    assert boxes.dtype == q.dtype == np.float32
    # the window's edges: an apex exactly on an edge is in
    edge = ramp_record(n=21, size=11, spacing=0.1, window_s=10e-9, labels=[lab(10, [9, 2e-9, 11, 6e-9], 0.3)])
    assert len(window_targets_m(edge, 0.0, 1.0, 100)[1]) == 1
    assert len(window_targets_m(edge, 1.0, 1.0, 100)[1]) == 1
    assert len(window_targets_m(edge, 1.0001, 1.0, 100)[1]) == 0
    empty_b, empty_q = window_targets_m(ramp_record(), 0, 1, 10)
    assert empty_b.shape == (0, 4) and empty_q.shape == (0,)


def test_a_box_a_pixel_tall_or_wide_is_kept():
    lab = {"apex_trace": 5, "box": [4.95, 2e-9, 5.05, 3e-9], "depth_m": 0.2}  # 1 px wide, 1 px tall
    rec = ramp_record(n=11, size=11, spacing=0.1, window_s=10e-9, labels=[lab])
    boxes, _ = window_targets_m(rec, 0.0, 1.0, 100)
    np.testing.assert_allclose(boxes, [[49.5, 2.5, 50.5, 3.5]], rtol=1e-6)


def test_a_time_crop_by_hand():
    labels = [{"apex_time_s": 4e-9, "depth_m": 0.1}, {"apex_time_s": 5e-9, "depth_m": 0.2},
              {"apex_time_s": 4.99e-9, "depth_m": 0.3}]
    rec = ramp_record(n=3, size=41, window_s=10e-9, labels=labels, direct_frac=0.1)
    c = crop_time(rec, 0.5)  # rows 0..20: 5 ns
    assert c.window_s == pytest.approx(5e-9, rel=1e-12)
    assert c.direct_frac == pytest.approx(0.2, rel=1e-12)
    assert [x["depth_m"] for x in c.labels] == [0.1, 0.3]
    np.testing.assert_allclose(c.proc[1], 2 * np.linspace(1, 21, 41), rtol=1e-6)
    assert (c.scale, c.offset_m, c.dt_s, c.eps_r) == (rec.scale, rec.offset_m, rec.dt_s, rec.eps_r)
    assert c.x_m is rec.x_m
    # never fewer than 8 rows' worth
    tiny = crop_time(rec, 0.01)
    assert tiny.window_s == pytest.approx(2e-9, rel=1e-12)
    assert crop_time(rec, 0.74).window_s == pytest.approx(7.5e-9, rel=1e-12)  # 29.6 rows: 30


def test_rois_and_their_split():
    rois = dn._rois([[[1, 2, 3, 4]], np.zeros((0, 4)), [[5, 6, 7, 8], [9, 10, 11, 12]]])
    np.testing.assert_array_equal(rois, [[0, 1, 2, 3, 4], [2, 5, 6, 7, 8], [2, 9, 10, 11, 12], [0, 0, 0, 1, 1]])
    assert rois.dtype == np.float32
    np.testing.assert_array_equal(dn._rois([[], []]), [[0, 0, 0, 1, 1]])
    parts = dn._split(np.array([10.0, 20.0, 30.0, 99.0]), [[[1, 2, 3, 4]], [], [[0] * 4, [1] * 4]])
    assert [p.tolist() for p in parts] == [[10.0], [], [20.0, 30.0]]


def test_the_loss_by_hand():
    torch = pytest.importorskip("torch")
    cfg = DepthTrainConfig(out="x", lambda_eps=2.0, lambda_depth=0.5)
    eps = torch.tensor([4.0, 9.0], requires_grad=True)
    q = torch.tensor([0.1, 0.3])
    loss, le, ld = dn._loss(eps, q, torch.tensor([8.0, 9.0]), torch.tensor([0.2, 0.1]), cfg)
    want_le = math.log(2.0) ** 2 / 2
    want_ld = (0.01 + 0.04) / 2 * 100
    assert le == pytest.approx(want_le, rel=1e-6) and ld == pytest.approx(want_ld, rel=1e-6)
    assert float(loss.detach()) == pytest.approx(2.0 * want_le + 0.5 * want_ld, rel=1e-6)
    # no boxes: the depth term is zero and the loss still reaches eps
    loss, le, ld = dn._loss(eps, torch.zeros(0), torch.tensor([8.0, 9.0]), torch.zeros(0), cfg)
    assert ld == 0.0 and float(loss.detach()) == pytest.approx(2.0 * want_le, rel=1e-6)
    loss.backward()
    assert eps.grad is not None and float(eps.grad[0]) == pytest.approx(2.0 * 2 * math.log(0.5) / 2 / 4.0, rel=1e-5)


# ------------------------------------------------------------------------------------------------ a training item

class Script:
    """A stand-in random generator answering from a script and recording each call."""

    def __init__(self, random=(), uniform=(), integers=()):
        self.r, self.u, self.i, self.calls = list(random), list(uniform), list(integers), []

    def random(self):
        self.calls.append("random")
        return self.r.pop(0)

    def uniform(self, a, b):
        self.calls.append(("uniform", a, b))
        return self.u.pop(0)

    def integers(self, n):
        self.calls.append(("integers", n))
        return self.i.pop(0)


def labelled_record():
    labels = [{"apex_trace": 20, "apex_time_s": 2e-9, "box": [15, 1e-9, 25, 3e-9], "depth_m": 0.1},
              {"apex_trace": 60, "apex_time_s": 3e-9, "box": [55, 2e-9, 65, 4e-9], "depth_m": 0.15}]
    rng = np.random.default_rng(4)
    rec = ramp_record(n=80, size=64, spacing=0.01, window_s=5e-9, labels=labels, direct_frac=0.3)
    rec.proc = rng.standard_normal(rec.proc.shape).astype(np.float32)
    return rec


def test_a_training_item_over_a_label_unmirrored():
    rec, cfg = labelled_record(), DepthConfig(size=64, alpha=0.5)
    rng = Script(random=[0.9, 0.5, 0.7], uniform=[0.1], integers=[1])
    image, boxes, q, direct, eps = dn._training_item(rec, cfg, rng)
    width = 0.5 * rec.depth_scale_m
    assert rng.calls == ["random", "random", ("integers", 2), ("uniform", -0.3, 0.3), "random"]
    want_img, left, w = depth_window(rec, 0.6 + 0.1 * width, cfg)
    np.testing.assert_array_equal(image, want_img)
    want_b, want_q = window_targets_m(rec, left, w, 64)
    np.testing.assert_array_equal(boxes, want_b)
    np.testing.assert_array_equal(q, want_q)
    assert (direct, eps) == (0.3, 6.0) and len(q) >= 1


def test_a_training_item_cropped_anywhere_and_mirrored():
    rec, cfg = labelled_record(), DepthConfig(size=64, alpha=0.5)
    rng = Script(random=[0.1, 0.95, 0.2], uniform=[0.6, 0.58])
    image, boxes, q, direct, eps = dn._training_item(rec, cfg, rng)
    assert rng.calls == ["random", ("uniform", pytest.approx(0.45, rel=1e-12), 1.0), "random",
                         ("uniform", 0.0, 0.79), "random"]
    c = crop_time(rec, 0.6)
    want_img, left, w = depth_window(c, 0.58, cfg)
    np.testing.assert_array_equal(image, want_img[:, :, ::-1])
    want_b, want_q = window_targets_m(c, left, w, 64)
    assert len(want_q) >= 1
    np.testing.assert_allclose(boxes, np.c_[64 - want_b[:, 2], want_b[:, 1], 64 - want_b[:, 0], want_b[:, 3]],
                               rtol=0, atol=1e-5)
    np.testing.assert_array_equal(q, want_q)
    assert direct == pytest.approx(c.direct_frac, rel=1e-12) and eps == 6.0


def test_a_crop_starts_past_the_direct_wave_and_at_least_at_35_percent():
    cfg = DepthConfig(size=64, alpha=0.5)
    for frac, low in [(0.1, 0.35), (0.5, 0.65), (0.95, 1.0)]:
        rec = labelled_record()
        rec.direct_frac = frac
        rng = Script(random=[0.0, 0.95, 0.9], uniform=[low, 0.3])
        dn._training_item(rec, cfg, rng)
        assert rng.calls[1][:2] == ("uniform", pytest.approx(low, rel=1e-12))


def test_a_record_without_labels_gives_windows_anywhere():
    rec, cfg = labelled_record(), DepthConfig(size=64, alpha=0.5)
    rec.labels = []
    rng = Script(random=[0.9, 0.9], uniform=[0.3])
    _, boxes, q, _, _ = dn._training_item(rec, cfg, rng)
    assert rng.calls == ["random", ("uniform", 0.0, 0.79), "random"] and boxes.shape == (0, 4) and q.size == 0


# ------------------------------------------------------------------------------------------------ cached records

def test_records_cached_and_loaded_back(tmp_path, monkeypatch):
    made = []

    def prepare(survey, labels, *, size):
        made.append((survey, size))
        rec = ramp_record(n=3, size=size, labels=labels["labels"], eps=labels["eps_r"])
        rec.proc = rec.proc / 7
        return rec

    monkeypatch.setattr(dn, "prepare_depth_record", prepare)
    source = lambda i: (f"survey{i}", {"eps_r": 4.0 + i, "labels": [{"depth_m": 0.1 * i}]})  # noqa: E731
    logged = []
    folder = dn.cache_depth_records(source, range(3), tmp_path / "a" / "cache", size=8, log=logged.append)
    assert folder == tmp_path / "a" / "cache" and made == [("survey0", 8), ("survey1", 8), ("survey2", 8)]
    assert sorted(p.name for p in folder.iterdir()) == ["rec_000000.npz", "rec_000001.npz", "rec_000002.npz"]
    recs = dn.load_depth_records(folder)
    assert [r.eps_r for r in recs] == [4.0, 5.0, 6.0]
    assert [r.labels for r in recs] == [[{"depth_m": 0.0}], [{"depth_m": 0.1}], [{"depth_m": 0.2}]]
    want = ramp_record(n=3, size=8)
    for r in recs:
        np.testing.assert_array_equal(r.proc, (want.proc / 7).astype(np.float16).astype(np.float32))
        assert r.proc.dtype == np.float32
        np.testing.assert_array_equal(r.x_m, want.x_m)
        assert (r.window_s, r.direct_frac, r.scale, r.offset_m, r.dt_s) == (10e-9, 0.1, 2.0, 0.05, 1e-11)
    # resumable: the ones there are kept; 50 new records logged
    made.clear()
    dn.cache_depth_records(source, range(52), folder, size=8, log=logged.append)
    assert len(made) == 49 and made[0][0] == "survey3"
    assert logged == []  # 49 new: none logged
    dn.cache_depth_records(source, range(60, 160), folder, size=8, log=logged.append)
    assert logged == [f"50 records prepared in {folder}", f"100 records prepared in {folder}"]
    assert not list(folder.glob("*.part"))


# ------------------------------------------------------------------------------------------------ training loop

def _stand_in_net(torch, seen):
    class Net(torch.nn.Module):
        """eps = 8 exp(a) for every window; depth fraction = b + box top / 1000."""

        def __init__(self):
            super().__init__()
            self.a = torch.nn.Parameter(torch.randn(()) * 0.1)
            self.b = torch.nn.Parameter(torch.randn(()) * 0.1)

        def forward(self, images, rois, direct):
            seen.append((images.detach().clone(), rois.detach().clone(), direct.detach().clone(),
                         self.a.detach().clone()))
            eps = 8.0 * torch.exp(self.a) + 0.0 * images.mean(dim=(1, 2, 3))
            return eps, self.b + rois[:, 2] / 1000.0

    return Net


@pytest.fixture
def stand_in(monkeypatch):
    torch = pytest.importorskip("torch")
    seen, built = [], []
    Net = _stand_in_net(torch, seen)

    def build(cfg=None):
        built.append(cfg)
        return Net()

    monkeypatch.setattr(dn, "build_depthnet", build)
    return {"seen": seen, "built": built, "torch": torch, "Net": Net}


def tcfg(tmp_path, **kw):
    base = dict(out=str(tmp_path / "run"), steps=4, batch=2, checkpoint_every=3, seed=5,
                net={"arch": "resnet10n", "width": 8, "size": 64, "alpha": 0.5})
    return DepthTrainConfig(**{**base, **kw})


def quiet(*a):
    pass


def test_training_draws_its_windows_from_the_step_s_seed(tmp_path, stand_in):
    recs = [labelled_record(), labelled_record()]
    recs[1].eps_r = 12.0
    nolabel = labelled_record()
    nolabel.eps_r = float("nan")  # left out
    cfg = tcfg(tmp_path)
    res = dn.train_depthnet(cfg, recs + [nolabel], log=quiet, progress=False)
    assert stand_in["built"] == [DepthConfig(width=8, size=64)]
    assert res["steps"] == 4 and res["parameters"] == 2 and res["net"] == DepthConfig(width=8, size=64)
    assert not res["model"].training
    net_cfg = DepthConfig(width=8, size=64)
    for step, (images, rois, direct, _) in enumerate(stand_in["seen"]):
        rng = np.random.default_rng(np.random.SeedSequence([5, step, 0xD3]))
        items = []
        for _ in range(2):
            k = int(rng.integers(2))
            items.append(dn._training_item(recs[k], net_cfg, rng, dn._smoothed(recs[k], net_cfg.alpha *
                                                                                 recs[k].depth_scale_m, 64)))
        np.testing.assert_array_equal(images.numpy(), np.stack([it[0] for it in items]))
        np.testing.assert_array_equal(rois.numpy(), dn._rois([it[1] for it in items]))
        np.testing.assert_allclose(direct.numpy(), [it[3] for it in items], rtol=1e-6)
    lines = (tmp_path / "run" / "losses.csv").read_text().splitlines()
    assert lines[0] == "step,lr,loss,log_eps_mse,depth_mse_x100,wall_s" and len(lines) == 5
    # the logged loss terms are the loss of what the stand-in answered
    images, rois, direct, a = stand_in["seen"][0]
    rng = np.random.default_rng(np.random.SeedSequence([5, 0, 0xD3]))
    ks = []
    for _ in range(2):
        k = int(rng.integers(2))
        ks.append(k)
        dn._training_item(recs[k], net_cfg, rng, None)
    le = np.mean([(math.log(8 * math.exp(float(a))) - math.log(recs[k].eps_r)) ** 2 for k in ks])
    step, lr, loss, log_le, log_ld, wall = lines[1].split(",")
    assert float(log_le) == pytest.approx(le, abs=6e-6)
    assert float(loss) == pytest.approx(float(log_le) + float(log_ld), abs=2e-5)
    # warm-up of max(steps // 10, 1) = 1 step, then the cosine: lr after step 1 is the full 1e-3
    assert [float(ln.split(",")[1]) for ln in lines[1:]] == pytest.approx(
        [1e-3 * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * (s - 1) / 3))) for s in (1, 2, 3, 4)], rel=2e-3)
    ck = stand_in["torch"].load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 4 and ck["gpr3d"] == __version__
    from dataclasses import asdict

    assert ck["resume_key"] == {k: v for k, v in asdict(cfg).items() if k not in ("out", "device", "checkpoint_every")}
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved == {"gpr3d": __version__, "config": asdict(cfg), "n_records": 2}


def test_training_stopped_and_resumed_ends_where_an_unbroken_run_ends(tmp_path, stand_in, monkeypatch):
    torch = stand_in["torch"]
    recs = [labelled_record()]
    whole = dn.train_depthnet(tcfg(tmp_path / "a"), recs, log=quiet, progress=False)
    saves = []
    real = torch.save
    monkeypatch.setattr(torch, "save", lambda state, f: (saves.append(state["step"]), real(state, f)))
    logged = []
    cfg = tcfg(tmp_path / "b")
    first = dn.train_depthnet(cfg, recs, log=logged.append, progress=False, max_seconds=0.0)
    assert first["steps"] == 1 and saves == [1]
    assert logged == ["stopped after 0 s at step 1; run again to continue"]
    logged.clear()
    again = dn.train_depthnet(cfg, recs, log=logged.append, progress=False)
    assert logged == ["resuming from step 1 of 4"] and saves == [1, 3, 4]
    assert torch.equal(again["model"].a, whole["model"].a) and torch.equal(again["model"].b, whole["model"].b)
    a = (tmp_path / "a" / "run" / "losses.csv").read_text().splitlines()
    b = (tmp_path / "b" / "run" / "losses.csv").read_text().splitlines()
    assert [ln.rsplit(",", 1)[0] for ln in b] == [ln.rsplit(",", 1)[0] for ln in a]
    for kw in ({"steps": 5}, {"batch": 3}, {"seed": 6}, {"lr": 2e-3}, {"lambda_eps": 0.5}, {"optimiser": "reference"}):
        with pytest.raises(GPR3DError) as err:
            dn.train_depthnet(tcfg(tmp_path / "b", **kw), recs, log=quiet, progress=False)
        assert str(err.value) == (f"{tmp_path / 'b' / 'run' / 'checkpoint.pt'}: made with other settings; use another "
                                  "--out or delete the checkpoint")
    dn.train_depthnet(tcfg(tmp_path / "b", checkpoint_every=1), recs, log=quiet, progress=False)  # how, not what


def test_training_needs_records_with_a_known_eps(tmp_path, stand_in):
    rec = labelled_record()
    rec.eps_r = float("nan")
    with pytest.raises(GPR3DError) as err:
        dn.train_depthnet(tcfg(tmp_path), [rec], log=quiet, progress=False)
    assert str(err.value) == "no records with a known eps_r to train DepthNet on"
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("opt, lr, cls, want_lr, wd", [("adamw", None, "AdamW", 1e-3, 1e-4),
                                                      ("reference", None, "SGD", 4e-5, 5e-5),
                                                      ("adamw", 3e-4, "AdamW", 3e-4, 1e-4)])
def test_training_optimisers(tmp_path, stand_in, opt, lr, cls, want_lr, wd):
    torch = stand_in["torch"]
    dn.train_depthnet(tcfg(tmp_path, optimiser=opt, lr=lr, steps=1), [labelled_record()], log=quiet, progress=False)
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    g = ck["optimizer"]["param_groups"][0]
    assert g["initial_lr"] == want_lr and g["weight_decay"] == wd
    assert ("momentum" in g and g["momentum"] == 0.9) == (cls == "SGD")
    assert ("betas" in g) == (cls == "AdamW")


def test_training_warm_up_is_a_tenth_of_the_steps_at_most_100(tmp_path, stand_in, monkeypatch):
    got = []
    real = dn.warmup_cosine
    monkeypatch.setattr(dn, "warmup_cosine", lambda w, s: (got.append((w, s)), real(w, s))[1])
    for steps in (1, 25, 50, 2000):
        cfg = tcfg(tmp_path / str(steps), steps=steps)
        dn.train_depthnet(cfg, [labelled_record()], log=quiet, progress=False, max_seconds=0.0)
    assert got == [(1, 1), (2, 25), (5, 50), (100, 2000)]


def test_training_from_given_weights(tmp_path, stand_in, monkeypatch):
    torch = stand_in["torch"]
    start = stand_in["Net"]()
    with torch.no_grad():
        start.a.fill_(0.25)
        start.b.fill_(-0.5)
    net = DepthConfig(width=8, size=64)
    monkeypatch.setattr(dn, "load_depthnet", lambda path: (start, net, {}))
    dn.train_depthnet(tcfg(tmp_path / "a", init="w.pt", steps=1), [labelled_record()], log=quiet, progress=False)
    assert float(stand_in["seen"][0][3]) == 0.25
    monkeypatch.setattr(dn, "load_depthnet", lambda path: (start, DepthConfig(width=16, size=64), {}))
    with pytest.raises(GPR3DError) as err:
        dn.train_depthnet(tcfg(tmp_path / "b", init="w.pt"), [labelled_record()], log=quiet, progress=False)
    assert str(err.value) == "--init w.pt: a DepthNet resnet10n width 16, not resnet10n width 8"


def test_training_shows_a_bar_only_when_asked(tmp_path, stand_in, capsys):
    dn.train_depthnet(tcfg(tmp_path / "a", steps=2), [labelled_record()], log=quiet, progress=False)
    assert capsys.readouterr().err == ""
    dn.train_depthnet(tcfg(tmp_path / "b", steps=2), [labelled_record()], log=quiet, progress=True)
    err = capsys.readouterr().err
    assert "train depthnet" in err and "2/2" in err and "eps=" in err and "depth=" in err


# ------------------------------------------------------------------------------------------------ the estimator

class Session:
    """A stand-in ONNX session: eps of window j of call c is 5 + j + 100 c, unless ``eps`` is given; depth fraction
    of a box is its window-pixel left edge / 1000."""

    def __init__(self, eps=None):
        self.calls, self.eps = [], eps

    def run(self, names, feeds):
        self.calls.append(feeds)
        b = len(feeds["images"])
        c = len(self.calls) - 1
        eps = (np.asarray(self.eps[16 * c: 16 * c + b], np.float32) if self.eps is not None
               else 5.0 + np.arange(b, dtype=np.float32) + 100 * c)
        return eps, feeds["rois"][:, 1] / 1000.0


def estimator(session, provenance=None, alpha=0.5, size=64):
    return DepthEstimator(None, DepthConfig(size=size, alpha=alpha), provenance, "cpu", session)


def test_the_estimate_with_boxes_one_window_each():
    rec = labelled_record()
    s = Session(eps=[6.0, 8.0, 7.0])
    est = estimator(s, {"validation": {"eps_rel_rmse": 0.1}})
    boxes = [[10, 1e-9, 30, 3e-9], [50, 2e-9, 70, 4e-9], [40, 1e-9, 44, 2e-9]]
    got = est.estimate(None, boxes, record=rec)
    (feeds,) = s.calls
    assert feeds["images"].shape == (3, 3, 64, 64) and feeds["images"].dtype == np.float32
    np.testing.assert_array_equal(feeds["direct"], np.full(3, 0.3, np.float32))
    # each window centred on its box; each box in its window's pixels
    for j, b in enumerate(boxes):
        img, left, w = depth_window(rec, rec.x_of_trace(0.5 * (b[0] + b[2])), est.net)
        np.testing.assert_array_equal(feeds["images"][j], img)
        np.testing.assert_allclose(feeds["rois"][j], [j, *box_to_window(rec, b, left, w, 64)], rtol=1e-6)
    np.testing.assert_array_equal(feeds["rois"][-1], [0, 0, 0, 1, 1])
    assert got["eps_r"] == 7.0 and got["n_windows"] == 3 and got["eps_r_windows"] == [6.0, 8.0, 7.0]
    spread = 1.4826 * 1.0 / math.sqrt(3)
    assert got["sigma_eps_r"] == pytest.approx(math.hypot(0.7, spread), rel=1e-12)
    d = rec.depth_scale_m
    np.testing.assert_allclose(got["depth_m"], [feeds["rois"][j, 1] / 1000.0 * d for j in range(3)], rtol=1e-6)


def test_the_estimate_without_boxes_tiles_the_record():
    rec = labelled_record()  # 0.79 m long; windows 0.375 m wide
    s = Session(eps=[6.0, 6.5, 7.0, 9.0, 30.0])
    got = estimator(s).estimate(None, [], record=rec)
    width = 0.5 * rec.depth_scale_m
    n = math.ceil(0.79 / (0.5 * width))
    assert got["n_windows"] == n == 5 and got["depth_m"] == []
    centres = np.linspace(0.0, 0.79, n + 1)[:n] + 0.25 * width
    for j, c in enumerate(centres):
        np.testing.assert_array_equal(s.calls[0]["images"][j], depth_window(rec, c, estimator(None).net)[0])
    np.testing.assert_array_equal(s.calls[0]["rois"], [[0, 0, 0, 1, 1]])
    assert got["eps_r"] == 7.0
    mad = np.median(np.abs(np.array([6.0, 6.5, 7.0, 9.0, 30.0]) - 7.0))  # 1.0
    assert got["sigma_eps_r"] == pytest.approx(math.hypot(0.15 * 7.0, 1.4826 * mad / math.sqrt(5)), rel=1e-12)


def test_one_window_has_no_spread_and_a_short_record_one_window():
    rec = labelled_record()
    rec.x_m = rec.x_m * 0.01  # 7.9 mm long
    s = Session(eps=[5.0, 5.0])
    got = estimator(s).estimate(None, [], record=rec)
    assert len(s.calls[0]["images"]) == 1 and got["n_windows"] == 1 and got["sigma_eps_r"] == pytest.approx(0.15 * 5.0, rel=1e-12)


def test_windows_go_to_the_network_sixteen_at_a_time():
    rec = labelled_record()
    s = Session()
    boxes = [[i, 1e-9, i + 10, 3e-9] for i in range(20)]
    got = estimator(s).estimate(None, boxes, record=rec)
    assert [len(c["images"]) for c in s.calls] == [16, 4]
    np.testing.assert_array_equal(s.calls[1]["rois"][:, 0], [0, 1, 2, 3, 0])
    assert got["eps_r_windows"] == [5.0 + j for j in range(16)] + [105.0, 106.0, 107.0, 108.0]
    d = rec.depth_scale_m
    np.testing.assert_allclose(got["depth_m"][16:], s.calls[1]["rois"][:4, 1] / 1000.0 * d, rtol=1e-6)
    np.testing.assert_allclose(got["depth_m"][:16], s.calls[0]["rois"][:16, 1] / 1000.0 * d, rtol=1e-6)


def test_the_torch_path_gives_what_the_model_gives():
    torch = pytest.importorskip("torch")
    seen = []
    Net = _stand_in_net(torch, seen)
    m = Net()
    with torch.no_grad():
        m.a.fill_(math.log(9.0 / 8.0))
        m.b.fill_(0.05)
    est = DepthEstimator(m, DepthConfig(size=64, alpha=0.5))
    rec = labelled_record()
    got = est.estimate(None, [[10, 1e-9, 30, 3e-9]], record=rec)
    assert got["eps_r"] == pytest.approx(9.0, rel=1e-6)
    _, rois, _, _ = seen[0]
    assert got["depth_m"][0] == pytest.approx((0.05 + float(rois[0, 2]) / 1000) * rec.depth_scale_m, rel=1e-6)


def test_validation_reports_the_errors_of_the_answers(monkeypatch):
    torch = pytest.importorskip("torch")
    from tests.inversion.test_depthnet import hyperbola_record

    Net = _stand_in_net(torch, [])
    m = Net()
    with torch.no_grad():
        m.a.fill_(math.log(6.0 / 8.0))  # eps 6 for every window
        m.b.fill_(0.0)
    recs = [hyperbola_record(spacing=0.02, eps=eps, length=1.0, ns=400) for eps in (5.0, 7.5)]
    got = dn.validate_depthnet(m, DepthConfig(size=64, alpha=0.5), lambda i: recs[i], 2)
    rel = np.array([6.0 / 5.0 - 1, 6.0 / 7.5 - 1])
    assert got["n_records"] == 2
    assert got["eps_rel_rmse"] == pytest.approx(float(np.sqrt(np.mean(rel ** 2))), rel=1e-5)
    assert got["eps_mape"] == pytest.approx(float(np.mean(np.abs(rel))), rel=1e-5)
    est = DepthEstimator(m, DepthConfig(size=64, alpha=0.5))
    errs = [abs(est.estimate(s, [lab["labels"][0]["box"]])["depth_m"][0] - 0.3) for s, lab in recs]
    assert got["depth_mae_m"] == pytest.approx(float(np.mean(errs)), rel=1e-5)


def test_weights_that_do_not_fit_are_named(tmp_path):
    torch = pytest.importorskip("torch")
    pytest.importorskip("torchvision")
    small = dn.build_depthnet(DepthConfig(width=8, size=64))
    dn.save_depthnet(small, DepthConfig(width=8, size=64), tmp_path / "w.pt", provenance={"made": "here"})
    model, net, prov = dn.load_depthnet(tmp_path / "w.pt")
    assert net == DepthConfig(width=8, size=64) and prov == {"made": "here"} and not model.training
    for k, v in small.state_dict().items():
        want = v.half().float() if v.is_floating_point() else v
        assert torch.equal(model.state_dict()[k], want), k
    obj = torch.load(tmp_path / "w.pt", weights_only=True)
    assert obj["format"] == "gpr3d.depthnet" and obj["version"] == 1
    obj["net"]["width"] = 16
    torch.save(obj, tmp_path / "bad.pt")
    with pytest.raises(FormatError) as err:
        dn.load_depthnet(tmp_path / "bad.pt")
    assert str(err.value) == "bad.pt: weights do not fit DepthNet resnet10n width 16"
    dn.save_depthnet(small, DepthConfig(width=8, size=64), tmp_path / "p.pt")
    assert dn.load_depthnet(tmp_path / "p.pt")[2] == {}


# ------------------------------------------------------------------------------------------------ the network

def _small_net(arch="resnet10n", width=8):
    torch = pytest.importorskip("torch")
    pytest.importorskip("torchvision")
    torch.manual_seed(0)
    return torch, dn.build_depthnet(DepthConfig(arch=arch, width=width, size=64)).eval()


def test_the_network_with_silent_heads_gives_eps_8_and_the_straight_ray_depth():
    """Heads zeroed: eps_r is the prior 8 and each box's depth fraction is its top's distance below the direct
    wave over sqrt(eps_r), (y0 / size - direct) / sqrt(8)."""
    torch, net = _small_net()
    with torch.no_grad():
        for head in (net.eps_head[-1], net.depth_head[-1]):
            head.weight.zero_()
            head.bias.zero_()
    images = torch.rand(2, 3, 64, 64)
    rois = torch.tensor([[0, 10, 20, 30, 40], [1, 5, 32, 60, 50], [1, 0, 0, 1, 1]], dtype=torch.float32)
    direct = torch.tensor([0.1, 0.25])
    with torch.no_grad():
        eps, q = net(images, rois, direct)
    np.testing.assert_allclose(eps.numpy(), [8.0, 8.0], rtol=1e-6)
    want = [(20 / 64 - 0.1) / math.sqrt(8), (32 / 64 - 0.25) / math.sqrt(8), (0 - 0.25) / math.sqrt(8)]
    np.testing.assert_allclose(q.numpy(), want, rtol=1e-5, atol=1e-7)


def test_the_network_clamps_eps_to_1_and_81():
    torch, net = _small_net()
    images, rois, direct = torch.rand(1, 3, 64, 64), torch.tensor([[0, 1.0, 2, 30, 40]]), torch.tensor([0.1])
    with torch.no_grad():
        net.eps_head[-1].weight.zero_()
        for bias, want in [(10.0, 81.0), (-10.0, 1.0), (math.log(2.0), 16.0)]:
            net.eps_head[-1].bias.fill_(bias)
            np.testing.assert_allclose(net(images, rois, direct)[0].numpy(), [want], rtol=1e-5)


def test_the_network_composes_its_parts():
    """eps from the pooled last stage and the direct wave; the RoI features are RoIAlign of the third stage at a
    16th of the picture; the depth head sees the RoI features, the box over the size, the direct wave, 1/sqrt(eps)
    and the top below the direct wave over sqrt(eps)."""
    torch, net = _small_net()
    from torchvision.ops import roi_align

    images = torch.rand(2, 3, 64, 64)
    rois = torch.tensor([[0, 10, 20, 30, 40], [1, 5, 32, 60, 50]], dtype=torch.float32)
    direct = torch.tensor([0.1, 0.25])
    got = {}
    net.roi_reduce.register_forward_hook(lambda m, i, o: got.__setitem__("roi_in", i[0].clone()))
    net.depth_head.register_forward_hook(lambda m, i, o: got.__setitem__("head_in", i[0].clone()))
    with torch.no_grad():
        eps, q = net(images, rois, direct)
        x = (images - 0.5) / 0.25
        f3 = net.layer3(net.layer2(net.layer1(net.stem(x))))
        f4 = net.layer4(f3)
        assert f3.shape == (2, 32, 4, 4) and f4.shape == (2, 64, 2, 2)
        want_eps = torch.exp(net.eps_head(torch.cat([f4.mean(dim=(2, 3)), direct[:, None]], 1))[:, 0]
                             + math.log(8.0))
        np.testing.assert_allclose(eps.numpy(), want_eps.numpy(), rtol=1e-5)
        np.testing.assert_allclose(got["roi_in"].numpy(),
                                   roi_align(f3, rois, output_size=7, spatial_scale=1 / 16, sampling_ratio=2,
                                             aligned=True).numpy(), rtol=1e-5, atol=1e-6)
        r = net.roi_fc(net.roi_reduce(got["roi_in"]).flatten(1))
        s = eps.rsqrt()
        bx = rois[:, 1:] / 64
        extra = torch.stack([bx[:, 0], bx[:, 1], bx[:, 2], bx[:, 3], direct, s, (bx[:, 1] - direct) * s], 1)
        np.testing.assert_allclose(got["head_in"].numpy(), torch.cat([r, extra], 1).numpy(), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(q.numpy(), (net.depth_head(got["head_in"])[:, 0] + (bx[:, 1] - direct) * s).numpy(),
                                   rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("arch, width, c3, c4", [("resnet10n", 8, 32, 64), ("resnet10n", 24, 96, 192),
                                                 ("resnet18", 8, 256, 512), ("resnet50", 8, 1024, 2048)])
def test_the_encoders_feed_heads_of_their_widths(arch, width, c3, c4):
    torch, net = _small_net(arch, width)
    assert net.eps_head[0].in_features == c4 + 1 and net.roi_reduce[0].in_channels == c3
    assert net.depth_head[0].in_features == 64 + 7 and net.roi_fc[0].in_features == 16 * 7 * 7
    with torch.no_grad():
        eps, q = net(torch.rand(1, 3, 64, 64), torch.tensor([[0, 1.0, 2, 30, 40]]), torch.tensor([0.1]))
    assert eps.shape == (1,) and q.shape == (1,) and 1.0 <= float(eps) <= 81.0
    if arch == "resnet10n":
        stem_conv = net.stem[0]
        assert (stem_conv.in_channels, stem_conv.out_channels, stem_conv.kernel_size, stem_conv.stride) == (
            3, width, (7, 7), (2, 2))
        assert [net.layer1.conv1.stride, net.layer2.conv1.stride, net.layer3.conv1.stride, net.layer4.conv1.stride] == [
            (1, 1), (2, 2), (2, 2), (2, 2)]
        assert net.layer1.downsample is None and net.layer2.downsample is not None
        assert [net.layer1.conv2.out_channels, net.layer2.conv2.out_channels] == [width, 2 * width]


def test_the_onnx_export_answers_as_pytorch_and_carries_its_metadata(tmp_path):
    pytest.importorskip("onnx")
    ort = pytest.importorskip("onnxruntime")
    import hashlib

    torch, net = _small_net()
    cfg = DepthConfig(width=8, size=64)
    dn.save_depthnet(net, cfg, tmp_path / "w.pt", provenance={"validation": {"eps_rel_rmse": 0.07}})
    info = dn.export_depthnet_onnx(tmp_path / "w.pt", tmp_path / "w.onnx")
    assert info["file"] == str(tmp_path / "w.onnx") and info["bytes"] == (tmp_path / "w.onnx").stat().st_size
    assert 0 <= info["max_diff"] < 1e-3
    assert not list(tmp_path.glob("*.part"))
    sess = ort.InferenceSession(str(tmp_path / "w.onnx"), providers=["CPUExecutionProvider"])
    assert [i.name for i in sess.get_inputs()] == ["images", "rois", "direct"]
    assert [o.name for o in sess.get_outputs()] == ["eps", "depth"]
    meta = json.loads(sess.get_modelmeta().custom_metadata_map["gpr3d.depthnet"])
    assert meta["net"] == {"arch": "resnet10n", "width": 8, "size": 64, "alpha": 0.5}
    assert meta["provenance"] == {"validation": {"eps_rel_rmse": 0.07}} and meta["opset"] == 17
    assert meta["source_weights"] == "w.pt"
    assert meta["source_sha256"] == hashlib.sha256((tmp_path / "w.pt").read_bytes()).hexdigest()
    # the estimator on the export and on the weights: the same answers; other batch sizes and box counts
    est_onnx, est_pt = DepthEstimator.load(tmp_path / "w.onnx"), DepthEstimator.load(tmp_path / "w.pt")
    assert est_onnx.session is not None and est_onnx.model is None and est_onnx.net == cfg
    assert est_onnx.provenance == {"validation": {"eps_rel_rmse": 0.07}} and est_pt.session is None
    assert est_pt.provenance == {"validation": {"eps_rel_rmse": 0.07}}
    rec = labelled_record()
    e1, q1 = est_onnx.predict(rec, [0.2, 0.5, 0.6], [[[15, 1e-9, 25, 3e-9]], [], [[55, 2e-9, 65, 4e-9]] * 2])
    e2, q2 = est_pt.predict(rec, [0.2, 0.5, 0.6], [[[15, 1e-9, 25, 3e-9]], [], [[55, 2e-9, 65, 4e-9]] * 2])
    np.testing.assert_allclose(e1, e2, rtol=1e-3)
    assert [len(q) for q in q1] == [1, 0, 2]
    np.testing.assert_allclose(np.concatenate(q1), np.concatenate(q2), rtol=1e-3, atol=1e-5)
    for centres, boxes in (([0.2], [[[15, 1e-9, 25, 3e-9]]]), ([0.2, 0.5], [[], []])):  # 2 and 1 RoIs, 1 and 2 windows
        e1, q1 = est_onnx.predict(rec, centres, boxes)
        e2, q2 = est_pt.predict(rec, centres, boxes)
        np.testing.assert_allclose(e1, e2, rtol=1e-3)
        np.testing.assert_allclose(np.concatenate(q1), np.concatenate(q2), rtol=1e-3, atol=1e-5)
    import onnx

    assert [(o.domain, o.version) for o in onnx.load(tmp_path / "w.onnx").opset_import] == [("", 17)]
    # the largest difference reported is the one the test windows show (eps relative, depth fractions absolute)
    images = np.random.default_rng(0).random((2, 3, 64, 64), dtype=np.float32)
    rois = dn._rois([[[20, 30, 90, 80]], [[100, 50, 200, 120], [10, 10, 60, 40]]])
    direct = np.array([0.1, 0.2], np.float32)
    got = sess.run(None, {"images": images, "rois": rois, "direct": direct})
    with torch.no_grad():
        ref = [x.numpy() for x in dn.load_depthnet(tmp_path / "w.pt")[0](torch.from_numpy(images),
                                                                          torch.from_numpy(rois),
                                                                          torch.from_numpy(direct))]
    assert info["max_diff"] == pytest.approx(max(float(np.max(np.abs(got[0] - ref[0]) / ref[0])),
                                                 float(np.max(np.abs(got[1] - ref[1])))), rel=1e-3, abs=1e-12)
    with pytest.raises(FormatError) as err:
        DepthEstimator.load(tmp_path / "none.onnx")
    assert str(err.value) == "none.onnx: no such ONNX DepthNet file"


# ------------------------------------------------------------------------------------------------ records by hand

def test_a_record_prepared_by_hand():
    from gpr3d.core.survey import Survey
    from gpr3d.inversion.hyperbola import direct_wave_time
    from gpr3d.processing.image import network_view, record_scale

    rng = np.random.default_rng(11)
    n, ns, dt = 12, 300, 5e-11
    data = 0.05 * rng.standard_normal((n, ns))
    data[:, 40:44] += [1.0, 3.0, -3.0, -1.0]  # a direct wave
    x = 2.0 + 0.03 * np.arange(n)
    x[5] = x[4]  # the cart stood still once
    s = Survey(data=data.astype(np.float32), dt_s=dt, positions_xyz=np.stack([x, 0 * x, 0 * x], 1), offset_m=0.08,
               frequency_hz=1e9)
    labs = [{"apex_trace": 3, "visible": True}, {"apex_trace": 5, "visible": False}, {"apex_trace": 7}]
    rec = dn.prepare_depth_record(s, {"eps_r": 7.5, "labels": labs})
    want_proc = network_view(s, 224)  # the default size
    assert rec.proc.shape == (n, 224)
    np.testing.assert_array_equal(rec.proc, want_proc)
    along = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(x)))])
    np.testing.assert_allclose(rec.x_m, along + np.arange(n) * 1e-9, rtol=0, atol=1e-12)
    assert np.all(np.diff(rec.x_m) > 0)
    window = (ns - 1) * dt
    assert (rec.window_s, rec.dt_s, rec.offset_m, rec.eps_r) == (window, dt, 0.08, 7.5)
    assert rec.direct_frac == direct_wave_time(s)[0] / window
    assert rec.scale == record_scale(want_proc)
    assert rec.labels == [labs[0], labs[2]] and rec.labels[0] is not labs[0]
    # no positions (a spacing instead), no offset, no eps_r
    s0 = Survey(data=data.astype(np.float32), dt_s=dt, offset_m=0.0, frequency_hz=1e9)
    for labels in (None, {"labels": labs}):
        r0 = dn.prepare_depth_record(s0, labels, size=64, trace_spacing_m=0.02)
        assert math.isnan(r0.eps_r) and r0.offset_m == 0.0 and r0.proc.shape == (n, 64)
        np.testing.assert_allclose(r0.x_m, np.arange(n) * (0.02 + 1e-9), rtol=0, atol=1e-12)


def test_window_columns_at_the_record_s_ends():
    """Traces at 0, 0.25 and 0.5 m (half a spacing: 0.125 m); columns 0.125 m wide centred at -0.125 ... 0.75 m."""
    rec = ramp_record(n=3, size=2, spacing=0.25)
    t = rec.proc.astype(np.float64)
    block = dn._columns(rec, -0.1875, 1.0, 8, rec.proc)
    want = [t[0], t[0], (t[0] + t[1]) / 2, t[1], (t[1] + t[2]) / 2, t[2], t[2], 0 * t[0]]  # the last lies outside
    np.testing.assert_allclose(block, want, rtol=1e-7)
    two = ramp_record(n=2, size=2, spacing=0.25)  # two traces still reach half a spacing past their ends
    t = two.proc.astype(np.float64)
    np.testing.assert_allclose(dn._columns(two, -0.1875, 1.0, 8, two.proc),
                               [t[0], t[0], (t[0] + t[1]) / 2, t[1], t[1], 0 * t[0], 0 * t[0], 0 * t[0]], rtol=1e-7)


def test_traces_box_filtered_by_hand_at_the_edges():
    three = ramp_record(n=3, size=2, spacing=0.01)
    t = three.proc.astype(np.float64)
    # four or five traces a column, wider than the record: the record's own odd width, three, the end traces
    # repeated beyond the ends
    for per in (4, 5):
        np.testing.assert_allclose(dn._smoothed(three, 8 * 0.01 * per, 8),
                                   [(2 * t[0] + t[1]) / 3, (t[0] + t[1] + t[2]) / 3, (t[1] + 2 * t[2]) / 3],
                                   rtol=1e-6)
    two = ramp_record(n=2, size=2, spacing=0.01)
    t = two.proc.astype(np.float64)
    np.testing.assert_allclose(dn._smoothed(two, 8 * 0.03, 8), [(2 * t[0] + t[1]) / 3, (t[0] + 2 * t[1]) / 3],
                               rtol=1e-6)
    exact = ramp_record(n=3, size=2, spacing=0.25)
    assert dn._smoothed(exact, 3.0, 8) is exact.proc  # 1.5 traces a column: not filtered


def test_window_targets_by_the_apex_not_the_box():
    """Traces 0.1 m apart, rows 0.1 ns apart; the window spans 0.2 .. 1.0 m in 64 columns."""
    labels = [
        {"apex_trace": 10.5, "box": [9, 0.5e-9, 11, 2e-9], "depth_m": 0.1},  # apex beyond the right edge: left out
        {"apex_trace": 3, "box": [2, 0.0, 4, 1e-9], "depth_m": 0.2},  # from the first row
        {"apex_trace": 5, "box": [4, 2e-9, 6, 2.04e-9], "depth_m": 0.3},  # under a pixel tall: left out
        {"apex_trace": 7, "box": [6, 3e-9, 8, 4e-9], "depth_m": 0.4},
    ]
    rec = ramp_record(n=13, size=64, spacing=0.1, window_s=6.3e-9, labels=labels)
    boxes, q = window_targets_m(rec, 0.2, 0.8, 64)
    np.testing.assert_allclose(boxes, [[0, 0.5, 16, 10.5], [32, 30.5, 48, 40.5]], rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(q, [0.2 / rec.depth_scale_m, 0.4 / rec.depth_scale_m], rtol=1e-6)


def test_a_mirrored_training_item_with_two_boxes():
    rec, cfg = labelled_record(), DepthConfig(size=64, alpha=0.5)
    rec.labels[0].update(apex_trace=40, box=[35, 1e-9, 45, 3e-9])
    rec.labels[1].update(apex_trace=50, box=[45, 2e-9, 55, 4e-9])
    rng = Script(random=[0.9, 0.5, 0.1], uniform=[0.0], integers=[0])
    image, boxes, q, _, _ = dn._training_item(rec, cfg, rng)
    want_img, left, w = depth_window(rec, 0.4, cfg)
    np.testing.assert_array_equal(image, want_img[:, :, ::-1])
    want_b, want_q = window_targets_m(rec, left, w, 64)
    assert len(want_b) == 2
    np.testing.assert_allclose(boxes, np.c_[64 - want_b[:, 2], want_b[:, 1], 64 - want_b[:, 0], want_b[:, 3]],
                               rtol=0, atol=1e-5)
    np.testing.assert_array_equal(q, want_q)


def test_records_are_cached_at_224_rows_unless_asked(tmp_path, monkeypatch):
    made = []

    def prepare(survey, labels, *, size):
        made.append(size)
        return ramp_record(n=3, size=4)

    monkeypatch.setattr(dn, "prepare_depth_record", prepare)
    dn.cache_depth_records(lambda i: ("s", {"labels": []}), [0], tmp_path, log=quiet)
    assert made == [224]


# ------------------------------------------------------------------------------------------------ training, more

def dense_record():
    """labelled_record's two targets over traces 2 mm apart: about three traces share each 5.9 mm column."""
    rec = labelled_record()
    rec.x_m = np.arange(400) * 0.002
    rec.proc = np.random.default_rng(8).standard_normal((400, 64)).astype(np.float32)
    for lab, apex in zip(rec.labels, (100, 300)):
        lab.update(apex_trace=apex, box=[apex - 25, lab["box"][1], apex + 25, lab["box"][3]])
    return rec


def test_training_windows_of_dense_traces_are_smoothed(tmp_path, stand_in):
    rec, net_cfg = dense_record(), DepthConfig(width=8, size=64)
    sm = dn._smoothed(rec, 0.5 * rec.depth_scale_m, 64)
    assert not np.array_equal(sm, rec.proc)
    dn.train_depthnet(tcfg(tmp_path, steps=1, seed=1), [rec], log=quiet, progress=False)  # a window not cut short
    rng = np.random.default_rng(np.random.SeedSequence([1, 0, 0xD3]))
    items = []
    for _ in range(2):
        rng.integers(1)
        items.append(dn._training_item(rec, net_cfg, rng, sm))
    np.testing.assert_array_equal(stand_in["seen"][0][0].numpy(), np.stack([it[0] for it in items]))


def test_the_logged_depth_loss_is_that_of_the_boxes_without_the_dummy(tmp_path, stand_in):
    torch = stand_in["torch"]
    rec, net_cfg = labelled_record(), DepthConfig(width=8, size=64)
    dn.train_depthnet(tcfg(tmp_path, steps=1, seed=5), [rec], log=quiet, progress=False)
    _, rois, _, a = stand_in["seen"][0]
    torch.manual_seed(5)  # the stand-in draws a, then b
    a0, b0 = float(torch.randn(()) * 0.1), float(torch.randn(()) * 0.1)
    assert a0 == float(a)
    rng = np.random.default_rng(np.random.SeedSequence([5, 0, 0xD3]))
    tq = []
    for _ in range(2):
        rng.integers(1)
        tq += list(dn._training_item(rec, net_cfg, rng, None)[2])
    q = b0 + rois.numpy()[:-1, 2] / 1000.0
    assert len(q) == len(tq) == len(set(tq)) >= 2  # windows over two targets
    line = (tmp_path / "run" / "losses.csv").read_text().splitlines()[1].split(",")
    assert float(line[4]) == pytest.approx(float(np.mean((q - np.asarray(tq)) ** 2) * 100), abs=2e-5)


def test_training_times_its_steps_and_stops_when_late(tmp_path, stand_in, monkeypatch, step_clock):
    monkeypatch.setattr(training, "time", step_clock())  # (the engine keeps the time)
    res = dn.train_depthnet(tcfg(tmp_path / "a"), [labelled_record()], log=quiet, progress=False)
    lines = (tmp_path / "a" / "run" / "losses.csv").read_text().splitlines()[1:]
    assert [ln.split(",")[-1] for ln in lines] == ["0.5", "1.0", "1.5", "2.0"] and res["wall_s"] == 2.5
    monkeypatch.setattr(training, "time", step_clock())  # (the engine keeps the time)
    logged = []
    res = dn.train_depthnet(tcfg(tmp_path / "b"), [labelled_record()], log=logged.append, progress=False,
                            max_seconds=1.0)
    # step 1 is logged at 0.5 s and checked at 1.0 s (not past 1 s); step 2 checked at 2.0 s
    assert res["steps"] == 2 and logged == ["stopped after 1 s at step 2; run again to continue"]


def test_training_s_bar_counts_on_from_where_it_resumes(tmp_path, stand_in, capsys):
    import re

    cfg = tcfg(tmp_path)
    dn.train_depthnet(cfg, [labelled_record()], log=quiet, progress=False, max_seconds=0.0)  # one step
    capsys.readouterr()
    dn.train_depthnet(cfg, [labelled_record()], log=quiet)  # the bar is shown by default
    last = capsys.readouterr().err.rstrip().split("\r")[-1]
    assert last.startswith("train depthnet: 100%") and "| 4/4 [" in last, last
    assert re.search(r"\d(step/s|s/step), depth=\d+\.\d{3}, eps=\d+\.\d{3}\]$", last), last


def test_a_run_whose_checkpoint_was_deleted_starts_a_new_log(tmp_path, stand_in):
    from dataclasses import asdict

    cfg = tcfg(tmp_path)
    dn.train_depthnet(cfg, [labelled_record()], log=quiet, progress=False)
    (tmp_path / "run" / "checkpoint.pt").unlink()
    dn.train_depthnet(cfg, [labelled_record()], log=quiet, progress=False)
    lines = (tmp_path / "run" / "losses.csv").read_text().splitlines()
    assert lines[0] == "step,lr,loss,log_eps_mse,depth_mse_x100,wall_s"
    assert [ln.split(",")[0] for ln in lines[1:]] == ["1", "2", "3", "4"]
    saved = (tmp_path / "run" / "config.json").read_text()
    assert saved == json.dumps({"gpr3d": __version__, "config": asdict(cfg), "n_records": 1}, indent=2)


def test_a_checkpoint_that_cannot_be_read_or_holds_code_is_named(tmp_path, stand_in):
    from fractions import Fraction

    torch = stand_in["torch"]
    ck = tmp_path / "run" / "checkpoint.pt"
    ck.parent.mkdir()
    ck.write_bytes(b"not a checkpoint")
    with pytest.raises(GPR3DError) as err:
        dn.train_depthnet(tcfg(tmp_path), [labelled_record()], log=quiet, progress=False)
    with pytest.raises(Exception) as direct:
        torch.load(ck, weights_only=True)
    assert str(err.value) == f"{ck}: cannot read the checkpoint ({type(direct.value).__name__}); delete it to restart"
    torch.save({"step": 1, "payload": Fraction(1, 3)}, ck)
    with pytest.raises(GPR3DError) as err:
        dn.train_depthnet(tcfg(tmp_path), [labelled_record()], log=quiet, progress=False)
    assert str(err.value) == f"{ck}: cannot read the checkpoint (UnpicklingError); delete it to restart"


def test_a_diverging_run_names_its_step(tmp_path, stand_in, monkeypatch):
    torch, Net = stand_in["torch"], stand_in["Net"]

    def build(cfg=None):
        net = Net()
        with torch.no_grad():
            net.a.fill_(float("nan"))
        return net

    monkeypatch.setattr(dn, "build_depthnet", build)
    with pytest.raises(GPR3DError) as err:
        dn.train_depthnet(tcfg(tmp_path), [labelled_record()], log=quiet, progress=False)
    assert str(err.value) == "DepthNet training diverged at step 0 (loss nan); lower --lr"


def test_training_starts_from_the_weights_file_it_is_given(tmp_path, stand_in, monkeypatch):
    asked = []
    monkeypatch.setattr(dn, "load_depthnet",
                        lambda path: (asked.append(path), stand_in["Net"](), DepthConfig(width=8, size=64), {})[1:])
    dn.train_depthnet(tcfg(tmp_path, init="start.pt", steps=1), [labelled_record()], log=quiet, progress=False)
    assert asked == ["start.pt"]


# ------------------------------------------------------------------------------------------------ the estimator, more

def test_the_estimator_smooths_dense_traces():
    rec = dense_record()
    s = Session(eps=[6.0])
    est = estimator(s)
    est.estimate(None, [[90, 1e-9, 110, 3e-9]], record=rec)
    img, _, _ = depth_window(rec, rec.x_of_trace(100.0), est.net)  # smoothed by itself
    np.testing.assert_array_equal(s.calls[0]["images"][0], img)


def test_the_estimate_of_a_survey_prepares_its_record_at_the_net_s_size():
    from gpr3d.core.survey import Survey

    rng = np.random.default_rng(12)
    data = 0.05 * rng.standard_normal((30, 200))
    data[:, 30:34] += [1.0, 3.0, -3.0, -1.0]
    s = Survey(data=data.astype(np.float32), dt_s=5e-11, frequency_hz=1e9)  # no positions: a spacing is needed
    sess = Session(eps=[6.0])
    est = estimator(sess)
    est.estimate(s, [[5, 1e-9, 15, 3e-9]], trace_spacing_m=0.01)
    rec = dn.prepare_depth_record(s, size=64, trace_spacing_m=0.01)
    np.testing.assert_array_equal(sess.calls[0]["images"][0], depth_window(rec, rec.x_of_trace(10.0), est.net)[0])


def test_the_tiles_follow_a_record_that_starts_past_zero():
    rec = ramp_record(n=9, size=64, spacing=0.1, window_s=5e-9)
    rec.x_m = rec.x_m + 1.0  # 1.0 .. 1.8 m; windows 0.375 m wide, a tile every 0.187 m
    s = Session(eps=[5.0] * 8)
    got = estimator(s).estimate(None, [], record=rec)
    assert got["n_windows"] == 5 and len(s.calls[0]["images"]) == 5  # ceil(0.8 / 0.1875)
    for j, c in enumerate(np.linspace(rec.x_m[0], rec.x_m[-1], 6)[:5] + 0.25 * 0.5 * rec.depth_scale_m):
        np.testing.assert_array_equal(s.calls[0]["images"][j], depth_window(rec, c, estimator(None).net)[0])


def test_two_windows_have_a_spread():
    s = Session(eps=[6.0, 9.0])
    got = estimator(s).estimate(None, [[10, 1e-9, 30, 3e-9], [50, 2e-9, 70, 4e-9]], record=labelled_record())
    assert got["eps_r"] == 7.5
    assert got["sigma_eps_r"] == pytest.approx(math.hypot(0.15 * 7.5, 1.4826 * 1.5 / math.sqrt(2)), rel=1e-12)


def test_validation_uses_the_visible_labels_only(monkeypatch):
    import warnings

    calls = []

    class Est:
        def __init__(self, model, net):
            pass

        def estimate(self, survey, boxes):
            calls.append(boxes)
            return {"eps_r": 6.0, "depth_m": [b[0] / 100 for b in boxes]}

    class Model:
        def eval(self):
            return self

    monkeypatch.setattr(dn, "DepthEstimator", Est)
    labs = [{"box": [10, 0, 20, 1], "depth_m": 0.05, "visible": True},
            {"box": [30, 0, 40, 1], "depth_m": 0.2, "visible": False}, {"box": [50, 0, 60, 1], "depth_m": 0.4}]
    got = dn.validate_depthnet(Model(), DepthConfig(), lambda i: ("s", {"eps_r": 5.0, "labels": labs}), 1)
    assert calls == [[[10, 0, 20, 1], [50, 0, 60, 1]]]
    assert got == {"n_records": 1, "eps_rel_rmse": pytest.approx(0.2), "eps_mape": pytest.approx(0.2),
                   "depth_mae_m": pytest.approx((0.05 + 0.1) / 2)}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no mean of nothing
        got = dn.validate_depthnet(Model(), DepthConfig(), lambda i: ("s", {"eps_r": 5.0, "labels": labs[1:2]}), 1)
    assert math.isnan(got["depth_mae_m"])


def test_weights_without_provenance_and_the_default_estimator(tmp_path):
    torch = pytest.importorskip("torch")
    pytest.importorskip("torchvision")
    pytest.importorskip("onnxruntime")
    dn.save_depthnet(dn.build_depthnet(DepthConfig(width=8, size=64)), DepthConfig(width=8, size=64), tmp_path / "w.pt")
    obj = torch.load(tmp_path / "w.pt", weights_only=True)
    del obj["provenance"]  # a file written before provenance was kept
    torch.save(obj, tmp_path / "old.pt")
    assert dn.load_depthnet(tmp_path / "old.pt")[2] == {}
    onnx = pytest.importorskip("onnx")
    est = DepthEstimator.load()  # the shipped ONNX export: its network as its metadata (read by onnx) says
    meta = {p.key: p.value for p in onnx.load(dn.DEFAULT_DEPTHNET).metadata_props}
    assert est.session is not None and est.net == DepthConfig(**json.loads(meta["gpr3d.depthnet"])["net"])


def test_onnx_files_that_are_not_depthnets_are_named(tmp_path):
    onnx = pytest.importorskip("onnx")
    ort = pytest.importorskip("onnxruntime")
    from dataclasses import asdict

    from onnx import TensorProto, helper

    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not onnx")
    with pytest.raises(FormatError) as err:
        dn._onnx_session(bad)
    with pytest.raises(Exception) as direct:
        ort.InferenceSession(str(bad), providers=["CPUExecutionProvider"])
    first = str(direct.value).splitlines()[0][:120]
    assert str(err.value) == f"bad.onnx: not a readable ONNX DepthNet ({type(direct.value).__name__}: {first})"
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, tmp_path / "plain.onnx")
    with pytest.raises(FormatError) as err:
        dn._onnx_session(tmp_path / "plain.onnx")
    assert str(err.value) == "plain.onnx: an ONNX file without gpr3d DepthNet metadata"
    entry = model.metadata_props.add()
    entry.key, entry.value = "gpr3d.depthnet", json.dumps({"net": asdict(DepthConfig(width=8, size=64))})
    onnx.save(model, tmp_path / "meta.onnx")
    _, net, prov = dn._onnx_session(tmp_path / "meta.onnx")
    assert net == DepthConfig(width=8, size=64) and prov == {}


# ------------------------------------------------------------------------------------------------ the network, more

def test_resnet10n_at_width_64_is_torchvision_s_resnet_with_one_basic_block_a_stage():
    torch = pytest.importorskip("torch")
    tvr = pytest.importorskip("torchvision.models.resnet")
    torch.manual_seed(1)
    ref = tvr.ResNet(tvr.BasicBlock, [1, 1, 1, 1]).eval()
    with torch.no_grad():  # running statistics that are not the identity
        for m in ref.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.2, 0.2)
                m.running_var.uniform_(0.5, 2.0)
    names = {"conv1.": "stem.0.", "bn1.": "stem.1."}
    state = {}
    for k, v in ref.state_dict().items():
        if k.startswith("fc."):
            continue
        head = next((a for a in names if k.startswith(a)), None)
        state[names[head] + k[len(head):] if head else k.replace(".0.", ".", 1)] = v
    net = dn.build_depthnet(DepthConfig(width=64, size=64)).eval()
    mine = {k for k in net.state_dict() if k.startswith(("stem.", "layer"))}
    assert mine == set(state)
    net.load_state_dict(state, strict=False)
    x = torch.rand(2, 3, 64, 64)
    with torch.no_grad():
        want = ref.layer4(ref.layer3(ref.layer2(ref.layer1(ref.maxpool(ref.relu(ref.bn1(ref.conv1(x))))))))
        got = net.layer4(net.layer3(net.layer2(net.layer1(net.stem(x)))))
    np.testing.assert_allclose(got.numpy(), want.numpy(), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("arch", ["resnet18", "resnet50"])
def test_a_torchvision_encoder_is_its_resnet_without_the_classifier(arch):
    torch = pytest.importorskip("torch")
    tvm = pytest.importorskip("torchvision.models")
    torch.manual_seed(2)
    ref = getattr(tvm, arch)(weights=None).eval()
    torch.manual_seed(2)
    net = dn.build_depthnet(DepthConfig(arch=arch, width=8, size=64)).eval()  # its encoder is made first
    x = torch.rand(1, 3, 64, 64)
    with torch.no_grad():
        want = ref.layer4(ref.layer3(ref.layer2(ref.layer1(ref.maxpool(ref.relu(ref.bn1(ref.conv1(x))))))))
        got = net.layer4(net.layer3(net.layer2(net.layer1(net.stem(x)))))
    assert torch.equal(got, want)


def test_the_heads_are_perceptrons_with_one_hidden_relu_layer():
    torch, net = _small_net()

    def params(module):
        return [p.detach().numpy().astype(np.float64) for p in module.parameters()]

    with torch.no_grad():
        for seq, n_in in ((net.eps_head, 65), (net.depth_head, 71)):
            x = torch.randn(5, n_in)
            w1, b1, w2, b2 = params(seq)
            want = np.maximum(x.numpy() @ w1.T + b1, 0) @ w2.T + b2
            got = seq(x).numpy()
            assert got.shape == (5, 1)
            np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)
        f = torch.randn(2, 32, 7, 7)
        w, b = params(net.roi_reduce)
        want = np.maximum(np.einsum("oc,nchw->nohw", w[:, :, 0, 0], f.numpy()) + b[None, :, None, None], 0)
        np.testing.assert_allclose(net.roi_reduce(f).numpy(), want, rtol=1e-4, atol=1e-5)
        v = torch.randn(2, 16 * 7 * 7)
        w, b = params(net.roi_fc)
        np.testing.assert_allclose(net.roi_fc(v).numpy(), np.maximum(v.numpy() @ w.T + b, 0), rtol=1e-4, atol=1e-5)
