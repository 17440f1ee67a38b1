"""Training-window augmentation (gpr3d.detection.augment): the record and its labels change together.

References: a record linear in the trace index (linear interpolation is exact on it), a synthetic
hyperbola whose drawn apex must stay under the stretched label, and draws worked out by hand."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.detection.augment import Augment, augment_record, stretch_labels, stretch_traces
from gpr3d.detection.data import random_window
from gpr3d.detection.windows import WindowConfig, make_window, prepare, record_scale, rows_interval, window_targets
from tests.detection.test_data_by_hand import Scripted


class Draws(Scripted):
    """The scripted generator of the window tests, answering normal() too (a constant 0.25 everywhere)."""

    def normal(self, loc, sd, size):
        self.calls.append(("normal", loc, sd, size))
        return np.full(size, 0.25)


def test_stretching_a_record_linear_in_its_traces_is_exact():
    n, rows = 21, 5
    i = np.arange(n, dtype=np.float32)[:, None]
    proc = (0.5 * i + np.arange(rows, dtype=np.float32)[None, :]).astype(np.float32)
    for s in (0.7, 1.0, 1.3, 2.0):
        out = stretch_traces(proc, s)
        m = int(round((n - 1) * s)) + 1
        assert out.shape == (m, rows) and out.dtype == np.float32
        # new column j holds old trace j / s (the last one clipped to the record's end)
        j = np.arange(m, dtype=np.float64)[:, None]
        want = 0.5 * np.minimum(j / s, n - 1) + np.arange(rows)[None, :]
        np.testing.assert_allclose(out, want, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(stretch_traces(proc, 1.0), proc)
    doubled = stretch_traces(proc, 2.0)
    np.testing.assert_array_equal(doubled[::2], proc)  # old traces at the even columns
    np.testing.assert_allclose(doubled[1::2], 0.5 * (proc[:-1] + proc[1:]), atol=1e-6)  # midpoints between


def test_a_two_trace_record_and_a_strong_shrink_keep_two_traces():
    proc = np.array([[1.0, 2.0], [3.0, 4.0]], np.float32)
    out = stretch_traces(proc, 0.3)  # round(1 x 0.3) + 1 = 1 -> at least 2
    assert out.shape == (2, 2)
    np.testing.assert_allclose(out[0], proc[0])
    np.testing.assert_allclose(out[1], proc[1])  # 1 / 0.3 is past the end: clipped to the last trace


def test_labels_follow_the_stretch_and_the_input_is_left_alone():
    labels = {"scene": 7, "labels": [
        {"box": [10.0, 1e-9, 20.0, 3e-9], "apex_trace": 15.0, "apex_time_s": 1.5e-9, "kind": "rebar"},
        {"box": [0.0, 2e-9, 4.0, 4e-9], "apex_trace": 2.0, "apex_time_s": 2.5e-9, "visible": False}]}
    out = stretch_labels(labels, 1.5)
    assert out["scene"] == 7
    assert out["labels"][0] == {"box": [15.0, 1e-9, 30.0, 3e-9], "apex_trace": 22.5, "apex_time_s": 1.5e-9,
                                "kind": "rebar"}
    assert out["labels"][1] == {"box": [0.0, 2e-9, 6.0, 4e-9], "apex_trace": 3.0, "apex_time_s": 2.5e-9,
                                "visible": False}
    assert labels["labels"][0]["box"] == [10.0, 1e-9, 20.0, 3e-9] and labels["labels"][0]["apex_trace"] == 15.0


def _hyperbola_record(n=120, rows=128, apex=47.0, dx=0.002, v=1e8, depth=0.15, dt=4e-11):
    """A point reflector: a Ricker wavelet on the two-way time curve; returns (Survey, labels)."""
    t = np.arange(rows) * dt
    x = (np.arange(n) - apex) * dx
    t0 = 2 * np.sqrt(depth**2 + x**2) / v
    f = 1.2e9
    arg = (np.pi * f * (t[None, :] - t0[:, None])) ** 2
    data = ((1 - 2 * arg) * np.exp(-arg)).astype(np.float32)
    s = Survey(data=data, dt_s=dt, frequency_hz=f)
    half = 12.0
    labels = {"labels": [{"box": [apex - half, 2 * depth / v - 0.6e-9, apex + half, 2 * depth / v + 1.5e-9],
                          "apex_trace": apex, "apex_time_s": 2 * depth / v, "visible": True}]}
    return s, labels


def test_the_stretched_hyperbola_s_apex_stays_under_its_stretched_label():
    s, labels = _hyperbola_record()  # the whole curve inside the record: every trace's peak is its arrival
    proc = s.data
    row = int(np.argmax(proc[47]))  # the apex row
    for factor in (0.75, 1.0, 1.37):
        out = stretch_traces(proc, factor)
        lab = stretch_labels(labels, factor)["labels"][0]
        # the earliest arrival (apex) is where the wavelet's peak row is smallest: the column under the label
        peak_rows = np.argmax(out, axis=1)
        top = np.nonzero(peak_rows == peak_rows.min())[0]
        assert abs(top.mean() - lab["apex_trace"]) <= 1.0, (factor, top, lab["apex_trace"])
        assert abs(np.argmax(out[int(round(lab["apex_trace"]))]) - row) <= 1
        assert 0 < top[0] and top[-1] < out.shape[0] - 1 and np.all(np.diff(top) == 1)  # one run of columns
        # the box keeps its share of the record
        assert lab["box"][2] - lab["box"][0] == pytest.approx(24.0 * factor)


def test_augment_record_draws_stretch_gain_noise_in_order():
    proc = np.linspace(-1, 1, 40, dtype=np.float32).reshape(10, 4)
    labels = {"labels": [{"box": [2.0, 0.0, 4.0, 1.0], "apex_trace": 3.0, "apex_time_s": 0.5}]}
    aug = Augment(stretch=(0.5, 2.0), gain=(0.25, 4.0), noise=0.4)
    # uniform draws in log space: log 1.5 for the stretch, log 2 for the gain, then a noise share of 0.1
    rng = Draws(uniforms=[np.log(1.5), np.log(2.0), 0.1])
    out, lab, scale = augment_record(proc, labels, 3.0, rng, aug)
    assert rng.calls[:3] == [("uniform", np.log(0.5), np.log(2.0)), ("uniform", np.log(0.25), np.log(4.0)),
                             ("uniform", 0.0, 0.4)]
    m = int(round(9 * 1.5)) + 1
    assert rng.calls[3] == ("normal", 0.0, pytest.approx(0.1 * 3.0), (m, 4))  # noise sd: share x the record's scale
    np.testing.assert_allclose(out, stretch_traces(proc, 1.5) + 0.25, atol=1e-6)
    assert scale == pytest.approx(3.0 / 2.0)
    assert lab["labels"][0]["box"] == [pytest.approx(3.0), 0.0, pytest.approx(6.0), 1.0]
    assert lab["labels"][0]["apex_trace"] == pytest.approx(4.5)


def test_an_augment_of_nothing_changes_nothing_and_draws_no_noise():
    proc = np.arange(12, dtype=np.float32).reshape(4, 3)
    labels = {"labels": [{"box": [0.0, 0.0, 1.0, 1.0], "apex_trace": 0.5, "apex_time_s": 0.1}]}
    rng = Draws()
    out, lab, scale = augment_record(proc, labels, 2.5, rng, Augment(stretch=(1, 1), gain=(1, 1), noise=0.0))
    assert rng.calls == []
    np.testing.assert_array_equal(out, proc)
    assert lab is labels and scale == 2.5


def test_the_defaults_and_their_bounds_are_refused_in_one_line():
    a = Augment()
    assert a.stretch == (0.7, 1.4) and a.gain == (0.6, 1.8) and a.noise == 0.15
    assert a.to_dict() == {"stretch": [0.7, 1.4], "gain": [0.6, 1.8], "noise": 0.15}
    assert Augment(**a.to_dict()) == a
    for kw, msg in ((dict(stretch=(1.4, 0.7)), r"augment stretch must satisfy 0.25 <= low <= high <= 4.0"),
                    (dict(stretch=(0.2, 1.0)), "augment stretch must satisfy"),
                    (dict(stretch=(1.0, 4.5)), "augment stretch must satisfy"),
                    (dict(gain=(0.05, 1.0)), r"augment gain must satisfy 0.1 <= low <= high <= 10.0"),
                    (dict(gain=(1.0, 11.0)), "augment gain must satisfy"),
                    (dict(gain=1.0), r"augment gain must be two numbers \(low, high\), got 1.0"),
                    (dict(stretch=("a", 1)), "augment stretch must be two numbers"),
                    (dict(noise=-0.1), "augment noise must lie in 0..1, got -0.1"),
                    (dict(noise=1.5), "augment noise must lie in 0..1"),
                    (dict(noise="0.1"), "augment noise must lie in 0..1")):
        with pytest.raises(InvalidDataError, match=msg):
            Augment(**kw)
    assert Augment(stretch=(0.25, 4.0), gain=(0.1, 10.0), noise=1.0).noise == 1.0  # the bounds themselves


def test_random_window_with_augment_is_the_window_of_the_augmented_record():
    s, labels = _hyperbola_record()
    cfg = WindowConfig(traces=32, rows=64)
    aug = Augment(stretch=(0.5, 2.0), gain=(0.5, 2.0), noise=0.2)
    # stretch 1.25, gain 1.6, noise share 0.05; then a window over the apex: start round(47 x 1.25 - 0.5 x 32)
    rng = Draws(uniforms=[np.log(1.25), np.log(1.6), 0.05, 0.5], randoms=[0.3, 0.9], integers=[0])
    image, boxes = random_window(s, labels, cfg, rng, augment=aug)
    proc = prepare(s, cfg)
    scale = record_scale(proc)
    big = stretch_traces(proc, 1.25) + np.float32(0.25)  # Draws' noise is 0.25 everywhere
    lab = stretch_labels(labels, 1.25)
    start = int(round(47 * 1.25 - 0.5 * 32))
    win = make_window(big, start, cfg, rows_interval(s, cfg), scale / 1.6)
    np.testing.assert_allclose(image, win.image, atol=1e-6)
    np.testing.assert_allclose(boxes, window_targets(lab["labels"], win), atol=1e-5)
    assert len(boxes) == 1
    # the box is centred on the stretched apex: 47 x 1.25 - start, in window pixels (pixel centres at +0.5)
    assert 0.5 * (boxes[0, 0] + boxes[0, 2]) == pytest.approx(47 * 1.25 - start + 0.5, abs=1e-4)
    assert boxes[0, 2] - boxes[0, 0] == pytest.approx(24 * 1.25, abs=1e-4)
    # without augment nothing of it is drawn and the window is the plain one
    rng = Draws(uniforms=[0.5], randoms=[0.3, 0.9], integers=[0])
    image, _ = random_window(s, labels, cfg, rng)
    assert [c[0] for c in rng.calls] == ["random", "integers", "uniform", "random"]
    plain = make_window(proc, int(round(47 - 16)), cfg, rows_interval(s, cfg), scale)
    np.testing.assert_array_equal(image, plain.image)


def test_the_dataset_passes_its_augment_to_every_window():
    torch = pytest.importorskip("torch")
    from gpr3d.detection.data import WindowDataset

    s, labels = _hyperbola_record()
    cfg = WindowConfig(traces=32, rows=64)
    aug = Augment()
    ds = WindowDataset(lambda i: (s, labels), 6, cfg, seed=5, augment=aug)
    assert ds.augment is aug and WindowDataset(lambda i: (s, labels), 6, cfg).augment is None
    for i in range(6):
        rng = np.random.default_rng(np.random.SeedSequence([5, i, 77]))
        img, boxes = random_window(s, labels, cfg, rng, augment=aug)
        got_img, got = ds[i]
        np.testing.assert_array_equal(got_img.numpy(), img)
        np.testing.assert_array_equal(got["boxes"].numpy(), boxes)
    plain = WindowDataset(lambda i: (s, labels), 6, cfg, seed=5)
    assert all(not torch.equal(ds[i][0], plain[i][0]) for i in range(6))
