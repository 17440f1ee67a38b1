"""B-scans as images (gpr3d.processing.image): row resampling, the 'hot' colours, window scaling and the whole-record
image, each against a reference written out here (np.interp, matplotlib's colour map, percentiles by hand)."""

import matplotlib
import numpy as np
import pytest

from gpr3d.core.survey import Survey
from gpr3d.processing.image import bscan_image, hot_rgb, normalise_window, resample_rows


@pytest.mark.parametrize("n_in, n_out", [(9, 4), (5, 13), (2, 7), (7, 2)])
def test_resample_rows_is_linear_interpolation_keeping_both_ends(n_in, n_out):
    rng = np.random.default_rng(n_in * 31 + n_out)
    x = rng.normal(size=(3, n_in)).astype(np.float32)
    got = resample_rows(x, n_out)
    t = np.linspace(0, n_in - 1, n_out)
    want = np.stack([np.interp(t, np.arange(n_in), row) for row in x.astype(np.float64)])
    assert got.dtype == np.float32 and got.shape == (3, n_out)
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-6)
    np.testing.assert_array_equal(got[:, 0], x[:, 0])
    np.testing.assert_allclose(got[:, -1], x[:, -1], rtol=0, atol=1e-6)


def test_resample_rows_to_the_same_length_is_a_copy():
    x = np.arange(12, dtype=np.float64).reshape(3, 4)
    got = resample_rows(x, 4)
    np.testing.assert_array_equal(got, x)
    assert got.dtype == np.float32
    got[0, 0] = 99
    assert x[0, 0] == 0  # not a view of the input


def test_hot_rgb_is_matplotlibs_hot_map_clipped_to_0_1():
    x = np.array([[-0.5, 0.0, 0.2], [0.5, 1.0, 3.0]])
    got = hot_rgb(x)
    cmap = matplotlib.colormaps["hot"]
    want = np.array([[cmap(v)[:3] for v in row] for row in np.clip(x, 0, 1)]) * 255
    assert got.dtype == np.uint8 and got.shape == (2, 3, 3)
    np.testing.assert_array_equal(got, want.astype(np.uint8))
    assert got[0, 0].tolist() == [10, 0, 0] and got[1, 1].tolist() == [255, 255, 255]  # near black to white
    assert got[0, 0].tolist() == got[0, 1].tolist() and got[1, 2].tolist() == got[1, 1].tolist()  # clipped
    assert got[0, 2, 0] > got[0, 2, 1] == 0  # dark red first


def test_normalise_window_by_its_percentile_or_a_given_scale():
    block = np.array([[0.0, 1.0, -2.0, 4.0], [8.0, -16.0, 3.0, 0.5]], np.float64)  # float64 in, float32 out
    p = float(np.percentile(np.abs(block), 99.5))  # 16 - 0.035 x 8: between the two largest
    np.testing.assert_allclose(normalise_window(block), np.clip(block / p, -1, 1), rtol=1e-6, atol=0)
    np.testing.assert_allclose(normalise_window(block, clip_percentile=50.0),
                               np.clip(block / float(np.median(np.abs(block))), -1, 1), rtol=1e-6, atol=0)
    got = normalise_window(block, scale=4.0)
    np.testing.assert_array_equal(got, np.clip(block / 4.0, -1, 1))
    assert got.dtype == np.float32 and got.max() == 1.0 and got.min() == -1.0
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        z = normalise_window(block, scale=bad)
        assert z.dtype == np.float32 and z.shape == block.shape and not z.any()
    assert not normalise_window(np.zeros((3, 3))).any()  # silence: no scale, zeros
    assert normalise_window(np.zeros((0, 4))).shape == (0, 4)


def test_bscan_image_is_the_hot_map_of_the_background_removed_envelope_free_amplitude():
    rng = np.random.default_rng(5)
    data = rng.normal(size=(6, 10)).astype(np.float32) + np.linspace(0, 3, 10, dtype=np.float32)  # a flat band
    s = Survey(data=data, dt_s=1e-10)
    img = bscan_image(s, 7)
    x = data.astype(np.float64) - data.astype(np.float64).mean(axis=0, keepdims=True)  # the band is gone
    t = np.linspace(0, 9, 7)
    a = np.abs(np.stack([np.interp(t, np.arange(10), row) for row in x]).T)  # (height, traces)
    want = hot_rgb(a / np.percentile(a, 99.5))
    assert img.shape == (7, 6, 3) and img.dtype == np.uint8
    assert np.abs(img.astype(int) - want.astype(int)).max() <= 1  # float32 against float64 rounding
    blank = bscan_image(Survey(data=np.ones((4, 5), np.float32), dt_s=1e-10), 5)  # all background: the map's 0
    assert (blank == hot_rgb(np.zeros(1))[0]).all() and blank[0, 0].tolist() == [10, 0, 0]


def _running_mean(x, w, axis):
    """A centred running mean of w samples with the ends repeated (scipy's 'nearest'), written out."""
    x = np.moveaxis(np.asarray(x, np.float64), axis, -1)
    left = w // 2
    pad = np.concatenate([np.repeat(x[..., :1], left, -1), x, np.repeat(x[..., -1:], w - 1 - left, -1)], -1)
    c = np.cumsum(np.concatenate([np.zeros(x.shape[:-1] + (1,)), pad], -1), -1)
    return np.moveaxis((c[..., w:] - c[..., :-w]) / w, -1, axis)


def _network_view_by_hand(data, dt, f, rows, dewow=True, background=True, equalise=True):
    d = np.asarray(data, np.float64)
    if dewow:
        w = int(np.clip(round(1 / (f * dt)), 3, d.shape[1] // 2 | 1))
        d = d - _running_mean(d, w, 1)
    if background:
        d = d - d.mean(axis=0)
    factor = d.shape[1] / rows
    if factor > 1.5:
        d = _running_mean(d, int(round(factor)), 1)
    t = np.linspace(0, d.shape[1] - 1, rows)
    out = np.stack([np.interp(t, np.arange(d.shape[1]), row) for row in d.astype(np.float32).astype(np.float64)])
    if equalise:
        rms = _running_mean(np.sqrt(np.mean(out**2, axis=0)), max(3, rows // 16), 0)
        out = out / np.maximum(rms, 0.05 * rms.max())
    return out


@pytest.mark.parametrize("n_samples, rows, freq", [(200, 64, 1e9), (100, 64, 1e9), (60, 64, None), (90, 60, 2e8)])
def test_network_view_by_hand(n_samples, rows, freq):
    from gpr3d.processing.image import network_view

    rng = np.random.default_rng(n_samples)
    tt = np.arange(n_samples)
    data = (rng.normal(size=(12, n_samples)) + 3 * np.sin(tt / 40.0) + 0.02 * tt  # wow and a flat band
            + 5 * np.exp(-0.5 * ((tt - 0.3 * n_samples) / 3) ** 2) * np.arange(12)[:, None] / 12).astype(np.float32)
    s = Survey(data=data, dt_s=1e-10, frequency_hz=freq)
    f = freq or 1.0 / (n_samples * 1e-10 / 20)  # no frequency: 20 periods in the window
    got = network_view(s, rows)
    assert got.dtype == np.float32 and got.shape == (12, rows)
    np.testing.assert_allclose(got, _network_view_by_hand(data, 1e-10, f, rows), rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(network_view(s, rows, dewow=False, background=False, equalise=False),
                               _network_view_by_hand(data, 1e-10, f, rows, False, False, False), rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(network_view(s, rows, equalise=False),
                               _network_view_by_hand(data, 1e-10, f, rows, equalise=False), rtol=2e-5, atol=2e-5)
    # the equalising step on its own (the detector equalises the plain view it keeps for the apexes): the bits of
    # the whole view, and the by-hand step on the plain one
    from gpr3d.processing.image import equalise_rows

    plain = network_view(s, rows, equalise=False)
    assert plain.dtype == np.float32
    eq = equalise_rows(plain)
    assert eq.dtype == np.float32 and np.array_equal(eq, got)
    rms = _running_mean(np.sqrt(np.mean(plain.astype(np.float64) ** 2, axis=0)), max(3, rows // 16), 0)
    np.testing.assert_allclose(eq, plain / np.maximum(rms, 0.05 * rms.max()), rtol=2e-6, atol=1e-6)


def test_network_view_of_silence_and_of_bad_records():
    from gpr3d.core.errors import InvalidDataError
    from gpr3d.processing.image import network_view

    flat = network_view(Survey(data=np.ones((4, 40), np.float32), dt_s=1e-10, frequency_hz=1e9), 32)
    assert flat.shape == (4, 32) and not flat.any()  # all background: zeros, no division by zero
    bad = np.ones((4, 40), np.float32)
    bad[1, 3] = np.nan
    with pytest.raises(InvalidDataError, match="^the record holds NaN/inf samples; detection needs finite data$"):
        network_view(_unchecked(bad), 32)
    for shape in ((1, 40), (4, 7)):
        with pytest.raises(InvalidDataError, match=rf"^a {shape[0]} x {shape[1]} record is too small to detect in$"):
            network_view(Survey(data=np.ones(shape, np.float32), dt_s=1e-10), 32)
    assert network_view(Survey(data=np.arange(16, dtype=np.float32).reshape(2, 8), dt_s=1e-10), 32).shape == (2, 32)


def _unchecked(data):
    """A stand-in record (Survey refuses NaN itself): only what network_view reads."""
    from types import SimpleNamespace

    return SimpleNamespace(data=data, dt_s=1e-10, frequency_hz=1e9)


@pytest.mark.parametrize("scale", [None, 2.0])
def test_render_channels_by_hand(scale):
    from scipy.signal import hilbert

    from gpr3d.processing.image import render_channels

    rng = np.random.default_rng(7)
    block = rng.normal(size=(10, 48)).astype(np.float32) * 1.5  # (traces, rows)
    img = render_channels(block, scale=scale)
    x = block.T.astype(np.float64)
    sc = scale if scale else np.percentile(np.abs(x), 99.5)
    x = np.clip(x / sc, -1, 1)
    env = np.abs(hilbert(x, axis=0))  # along time (rows)
    gained = np.clip(x * np.linspace(0.5, 1.5, 48)[:, None], -1, 1)
    assert img.dtype == np.float32 and img.shape == (3, 48, 10)
    np.testing.assert_allclose(img[0], 0.5 + 0.5 * x, rtol=0, atol=1e-6)
    np.testing.assert_allclose(img[1], np.clip(env, 0, 1), rtol=0, atol=1e-5)
    np.testing.assert_allclose(img[2], 0.5 + 0.5 * gained, rtol=0, atol=1e-6)
    assert img.min() >= 0 and img.max() <= 1 and img[1].max() == 1.0  # the envelope is clipped at 1
    hot = render_channels(block, "hot", scale=scale)
    want = hot_rgb(np.clip(env, 0, 1)).transpose(2, 0, 1) / 255.0
    assert hot.dtype == np.float32 and hot.flags["C_CONTIGUOUS"] and hot.shape == (3, 48, 10)
    assert np.abs(hot - want).max() <= 1 / 255 + 1e-6


def test_record_scale_is_the_99_5th_percentile_or_one():
    from gpr3d.processing.image import record_scale

    x = np.random.default_rng(1).normal(size=(20, 30))
    assert record_scale(x) == pytest.approx(np.percentile(np.abs(x), 99.5), rel=1e-15, abs=0)
    assert record_scale(x) < np.abs(x).max()
    assert record_scale(np.zeros((3, 3))) == 1.0


def test_hot_rgb_clips_before_the_colour_map():
    x = np.array([-5.0, 0.0, 1.0, 1.5, 40.0])
    got = hot_rgb(x)
    cmap = matplotlib.colormaps["hot"]
    assert got[0].tolist() == got[1].tolist() == [int(c * 255) for c in cmap(0.0)[:3]]
    assert got[2].tolist() == got[3].tolist() == got[4].tolist() == [255, 255, 255]
