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
    block = np.array([[0.0, 1.0, -2.0, 4.0], [8.0, -16.0, 3.0, 0.5]], np.float32)
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
