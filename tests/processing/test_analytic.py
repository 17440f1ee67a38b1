"""The NumPy envelope and running mean against SciPy's and against closed forms."""

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d
from scipy.signal import hilbert

from gpr3d.processing.analytic import analytic, fast_length, hilbert_envelope, running_mean


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 8, 33, 64])
@pytest.mark.parametrize("axis", [0, 1, -1])
def test_analytic_equals_scipy_hilbert(n, axis):
    rng = np.random.default_rng(n)
    x = rng.standard_normal((n, 5) if axis == 0 else (5, n))
    got = analytic(x, axis=axis)
    want = hilbert(x, axis=axis)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # the real part is the signal itself
    np.testing.assert_allclose(got.real, x, rtol=0, atol=1e-12)


def test_analytic_of_a_three_axis_block_along_the_middle():
    x = np.random.default_rng(3).standard_normal((3, 10, 4))
    np.testing.assert_allclose(analytic(x, axis=1), hilbert(x, axis=1), rtol=0, atol=1e-12)


def test_single_precision_stays_single_and_matches():
    x = np.random.default_rng(1).standard_normal((16, 40)).astype(np.float32)
    got = analytic(x, axis=0)
    assert got.dtype == np.complex64
    np.testing.assert_allclose(got, hilbert(x, axis=0), rtol=0, atol=1e-5)


def test_envelope_along_either_axis():
    t = np.arange(128)
    x = np.stack([np.cos(2 * np.pi * 9 * t / 128), 2 * np.cos(2 * np.pi * 20 * t / 128)])  # (2, 128)
    np.testing.assert_allclose(hilbert_envelope(x.T, axis=0), [[1.0, 2.0]] * 128, rtol=1e-12)
    np.testing.assert_allclose(hilbert_envelope(x, axis=1), np.abs(hilbert(x, axis=1)), atol=1e-12)


def test_envelope_of_a_cosine_is_its_amplitude():
    # whole periods: the Hilbert transform of cos is sin exactly, so the envelope is flat
    t = np.arange(256)
    for amp, periods in [(1.0, 5), (3.5, 17), (0.25, 64)]:
        x = amp * np.cos(2 * np.pi * periods * t / t.size + 0.3)
        np.testing.assert_allclose(hilbert_envelope(x), amp, rtol=1e-12)
        np.testing.assert_allclose(analytic(x).imag, amp * np.sin(2 * np.pi * periods * t / t.size + 0.3),
                                   atol=1e-12)


def test_odd_length_has_no_nyquist_bin():
    # n = 9: bins 1..4 doubled, none kept at one; an even-n rule would halve bin 4 or 5
    x = np.cos(2 * np.pi * 4 * np.arange(9) / 9)
    np.testing.assert_allclose(hilbert_envelope(x), 1.0, rtol=1e-12)


def test_integers_are_read_as_float64_and_complex_refused():
    x = np.arange(12) % 5
    np.testing.assert_allclose(analytic(x), hilbert(x.astype(float)), atol=1e-12)
    with pytest.raises(ValueError, match="^the analytic signal is made from real samples$"):
        analytic(np.ones(4, complex))
    with pytest.raises(ValueError, match="^the analytic signal needs at least one sample along its axis$"):
        analytic(np.ones((3, 0)), axis=1)


@pytest.mark.parametrize("size", [1, 2, 3, 4, 5, 8, 11, 40])
@pytest.mark.parametrize("n", [1, 3, 6, 25])
def test_running_mean_equals_uniform_filter1d_nearest(size, n):
    rng = np.random.default_rng(size * 100 + n)
    x = rng.standard_normal((4, n)) * 1e3 + 5e3
    for axis in (1, -1):
        np.testing.assert_allclose(running_mean(x, size, axis=axis),
                                   uniform_filter1d(x, size, axis=axis, mode="nearest"), rtol=1e-12)
    np.testing.assert_allclose(running_mean(x.T, size, axis=0),
                               uniform_filter1d(x.T, size, axis=0, mode="nearest"), rtol=1e-12)


def test_running_mean_by_hand():
    x = np.array([1.0, 2.0, 4.0, 8.0, 16.0])
    # size 3: the first sample averages [1, 1, 2] (the end copied), the last [8, 16, 16]
    np.testing.assert_allclose(running_mean(x, 3), [4 / 3, 7 / 3, 14 / 3, 28 / 3, 40 / 3])
    # size 2 reaches one back: sample i is the mean of i-1 and i
    np.testing.assert_allclose(running_mean(x, 2), [1.0, 1.5, 3.0, 6.0, 12.0])
    # a ramp is its own running mean away from the ends
    ramp = np.arange(20.0)
    np.testing.assert_allclose(running_mean(ramp, 5)[2:-2], ramp[2:-2], rtol=1e-14)


def test_running_mean_types_and_limits():
    x32 = np.linspace(0, 1, 9, dtype=np.float32)
    assert running_mean(x32, 3).dtype == np.float32
    assert running_mean(np.arange(6), 2).dtype == np.float64
    np.testing.assert_allclose(running_mean(np.arange(6), 2), uniform_filter1d(np.arange(6.0), 2, mode="nearest"))
    empty = running_mean(np.ones((2, 0), np.float32), 3, axis=1)
    assert empty.shape == (2, 0) and empty.dtype == np.float32
    assert running_mean(np.ones((2, 0), np.int16), 3, axis=1).dtype == np.float64
    with pytest.raises(ValueError, match="at least 1, not 0"):
        running_mean(np.ones(4), 0)


@pytest.mark.parametrize("m, n", [(7, 8), (16, 32), (29, 60), (5, 5)])
def test_zero_padding_equals_scipy_with_n_cut_back(m, n):
    x = np.random.default_rng(m).standard_normal((3, m))
    got = analytic(x, axis=1, n=n)
    assert got.shape == (3, m)
    np.testing.assert_allclose(got, hilbert(x, N=n, axis=1)[:, :m], rtol=0, atol=1e-12)
    np.testing.assert_allclose(hilbert_envelope(x.T, axis=0, n=n), np.abs(hilbert(x, N=n, axis=1)[:, :m]).T,
                               atol=1e-12)
    with pytest.raises(ValueError, match=f"the FFT's length {m - 1} is shorter than the {m} samples"):
        analytic(x, axis=1, n=m - 1)


def test_fast_lengths_are_the_smallest_5_smooth_ones():
    def smooth(k):
        for p in (2, 3, 5):
            while k % p == 0:
                k //= p
        return k == 1

    for m in range(1, 400):
        want = next(k for k in range(m, 4 * m + 2) if smooth(k))
        assert fast_length(m) == want, m


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("m, n", [(8, None), (9, None), (8, 20), (9, 27), (1, None)])
def test_the_envelope_by_the_real_fft_equals_the_analytic_signal_s_magnitude(dtype, m, n):
    x = np.random.default_rng(m).standard_normal((4, m)).astype(dtype)
    got = hilbert_envelope(x, axis=1, n=n)
    assert got.dtype == dtype and got.shape == x.shape
    want = np.abs(hilbert(x.astype(np.float64), N=n or m, axis=1)[:, :m])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 if dtype == np.float32 else 1e-12)
    for bad, msg in ((x + 1j, "made from real samples"), (np.zeros((3, 0)), "at least one sample"),
                     (x, f"the FFT's length {m - 1} is shorter")):
        with pytest.raises(ValueError, match=msg):
            hilbert_envelope(bad, axis=1, n=m - 1 if "FFT" in msg else None)
