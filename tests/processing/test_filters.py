"""Processing against independent references: explicit convolutions, analytic signals, closed forms."""

import numpy as np
import pytest
from scipy import signal

from gpr3d.processing import (
    bandpass,
    dewow,
    envelope,
    gain_agc,
    gain_sec,
    gain_tpow,
    remove_background,
    remove_dc,
    resample_traces,
)
from gpr3d.processing.background import moving_background

DT = 0.1e-9


def test_dewow_equals_explicit_running_mean():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, 400)).astype(np.float32)
    window = 2.05e-9  # -> 21 samples (odd)
    got = dewow(x, DT, window)
    # interior: x - mean of the 21 samples around each sample
    ref = x - np.stack([np.convolve(r.astype(float), np.ones(21) / 21, mode="same") for r in x])
    np.testing.assert_allclose(got[:, 10:-10], ref[:, 10:-10], atol=1e-5)
    # the ends: the window runs over the edge sample repeated (not zeros, not a shorter window)
    padded = np.pad(x.astype(float), ((0, 0), (10, 10)), mode="edge")
    ref_all = x - np.stack([np.convolve(r, np.ones(21) / 21, mode="valid") for r in padded])
    np.testing.assert_allclose(got, ref_all, atol=1e-5)


def test_dewow_window_rounding_and_output_type():
    """The window in samples: rounded, made odd by adding one (an odd count stays), at least two samples before
    that; float32 out whatever comes in."""
    rng = np.random.default_rng(2)
    x = rng.standard_normal((2, 300))
    for window, n in ((2.1e-9, 21), (2.0e-9, 21), (2 * DT, 3)):  # 21 stays 21; 20 -> 21; 2 -> 3
        padded = np.pad(x, ((0, 0), (n // 2, n // 2)), mode="edge")
        ref = x - np.stack([np.convolve(r, np.ones(n) / n, mode="valid") for r in padded])
        got = dewow(x, DT, window)
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, ref, atol=1e-5)
    with pytest.raises(ValueError, match="shorter than two samples"):
        dewow(x, DT, 1.4 * DT)


def test_dewow_removes_a_slow_trend_and_keeps_a_wavelet():
    t = np.arange(600) * DT
    wow = 5.0 * np.exp(-t / 30e-9)
    wav = signal.gausspulse(t - 30e-9, fc=1e9, bw=0.5)
    out = dewow((wow + wav)[None, :], DT, 1e-9)[0]
    assert np.max(np.abs(out[20:-20] - wav[20:-20])) < 0.15
    assert np.abs(out[50:250].mean()) < 0.02


def test_background_mean_median_and_window():
    rng = np.random.default_rng(1)
    band = rng.standard_normal(50)
    x = (band[None, :] + 0.1 * rng.standard_normal((30, 50))).astype(np.float32)
    np.testing.assert_allclose(remove_background(x), x - x.mean(axis=0), atol=1e-5)
    np.testing.assert_allclose(remove_background(x, method="median"), x - np.median(x, axis=0), atol=1e-6)
    w = remove_background(x, window_traces=5)
    np.testing.assert_allclose(w[10], x[10] - x[8:13].mean(axis=0), atol=1e-5)
    # the windowed median: over 5 neighbouring traces, sample by sample (not along time)
    wm = remove_background(x, method="median", window_traces=5)
    np.testing.assert_allclose(wm[10], x[10] - np.median(x[8:13], axis=0), atol=1e-6)
    np.testing.assert_allclose(wm[0], x[0] - np.median(x[[0, 0, 0, 1, 2]], axis=0), atol=1e-6)  # edge repeated
    with pytest.raises(ValueError, match="unknown background method"):
        remove_background(x, method="mode")


def test_remove_dc():
    x = np.arange(20, dtype=np.float32).reshape(2, 10) + np.array([[5.0], [-3.0]], dtype=np.float32)
    np.testing.assert_allclose(remove_dc(x).mean(axis=1), 0, atol=1e-6)
    np.testing.assert_allclose(remove_dc(x, sample_range=(0, 2))[:, 0], [-0.5, -0.5])
    np.testing.assert_allclose(remove_dc(x, sample_range=(3, 4)), x - x[:, 3:4])  # one sample is enough
    assert remove_dc(x.astype(np.float64)).dtype == np.float32
    with pytest.raises(ValueError, match=r"sample_range \(5, 5\) selects no samples"):
        remove_dc(x, sample_range=(5, 5))


def test_background_window_edges_and_limits():
    """A window of all traces (or more) is the whole-survey background; 2 traces is the smallest (the trace and
    the one before it, by scipy's convention for even windows); the ends repeat the edge trace."""
    rng = np.random.default_rng(8)
    x = rng.standard_normal((30, 50)).astype(np.float32)
    whole = x - x.mean(axis=0)
    for w in (30, 40):  # 40 traces: more than there are (fewer than the 50 samples)
        np.testing.assert_allclose(remove_background(x, window_traces=w), whole, atol=1e-5)
    two = remove_background(x, window_traces=2)
    np.testing.assert_allclose(two[5], x[5] - (x[4] + x[5]) / 2, atol=1e-6)
    five = remove_background(x, window_traces=5)
    np.testing.assert_allclose(five[0], x[0] - x[[0, 0, 0, 1, 2]].mean(axis=0), atol=1e-6)  # nearest, not reflect
    np.testing.assert_allclose(five[29], x[29] - x[[27, 28, 29, 29, 29]].mean(axis=0), atol=1e-6)
    for method in ("mean", "median"):
        assert remove_background(x.astype(np.float64), method=method).dtype == np.float32
        assert remove_background(x, method=method, window_traces=3).dtype == np.float32
    with pytest.raises(ValueError, match="^window_traces must be >= 2, got 1$"):
        remove_background(x, window_traces=1)


def test_gains_closed_form():
    x = np.ones((2, 100), dtype=np.float32)
    t = np.arange(100) * DT
    t0 = 2e-9
    tp = np.maximum(t - t0, 0)
    np.testing.assert_allclose(gain_tpow(x, DT, power=2, t0_s=t0)[0], np.maximum(tp / 1e-9, 1) ** 2, rtol=1e-6)
    g = gain_sec(x, DT, alpha_per_s=1e8, power=1, t0_s=t0, max_gain=None)[0]
    np.testing.assert_allclose(g, np.maximum(tp / 1e-9, 1) * np.exp(1e8 * tp), rtol=1e-6)
    assert gain_sec(x, DT, alpha_per_s=1e10, max_gain=50)[0].max() == pytest.approx(50)


def test_gain_defaults_by_hand():
    """The defaults, each against its closed form: the plain curve is flat; t-power is (t / 1 ns)^1 from t = 0;
    SEC is (t / 1 ns) exp(alpha t) capped at 1e6; t_ref is passed through."""
    from gpr3d.processing.gain import gain_curve_sec

    t = np.arange(100) * DT
    np.testing.assert_array_equal(gain_curve_sec(100, DT), np.ones(100))
    np.testing.assert_allclose(gain_curve_sec(100, DT, power=1.0), np.maximum(t / 1e-9, 1.0), rtol=1e-12)
    x = np.full((2, 100), 2.0)
    out = gain_tpow(x, DT)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out[1], 2.0 * np.maximum(t / 1e-9, 1.0), rtol=1e-6)
    np.testing.assert_allclose(gain_tpow(x, DT, t_ref_s=2e-9)[0], 2.0 * np.maximum(t / 2e-9, 1.0), rtol=1e-6)
    sec = gain_sec(x, DT, alpha_per_s=5e7)
    assert sec.dtype == np.float32
    np.testing.assert_allclose(sec[0], 2.0 * np.maximum(t / 1e-9, 1.0) * np.exp(5e7 * t), rtol=1e-6)
    np.testing.assert_allclose(gain_sec(x, DT, alpha_per_s=0.0, t_ref_s=4e-9)[0], 2.0 * np.maximum(t / 4e-9, 1.0),
                               rtol=1e-6)
    big = gain_sec(np.ones((1, 100)), DT, alpha_per_s=3e9)[0]  # exp(3e9 t) passes 1e6 within the record
    assert big.max() == 1e6 and np.sum(big == 1e6) > 10


def test_agc_by_hand():
    """AGC divides by the RMS over a centred window (edges repeat the end sample), never by less than eps times the
    whole record's RMS; a window under one sample is one sample (sign of the data); silent data stay zero."""
    x = np.array([[3.0, -4.0, 0.0, 1e-6, 5.0, 0.0, -2e-6, 12.0]])
    out = gain_agc(x, DT, window_s=5 * DT)[0]
    assert gain_agc(x, DT, window_s=5 * DT).dtype == np.float32
    floor = 1e-3 * np.sqrt(np.mean(x * x))
    padded = np.pad(x[0], 2, mode="edge")
    rms = np.sqrt(np.convolve(padded ** 2, np.ones(5) / 5, mode="valid"))
    np.testing.assert_allclose(out, x[0] / np.maximum(rms, floor), rtol=1e-6)
    np.testing.assert_allclose(out[0], 3.0 / np.sqrt((9 + 9 + 9 + 16 + 0) / 5), rtol=1e-6)  # edge: 3 repeated
    tiny = gain_agc(np.array([[1.0, 1e-9, 1e-9, 1e-9, 1e-9, 1e-9, 1e-9, 1.0]]), DT, window_s=DT)[0]
    np.testing.assert_allclose(tiny[3], 1e-9 / (1e-3 * np.sqrt(2 / 8)), rtol=1e-6)  # held up by the floor
    one = gain_agc(x, DT, window_s=0.2 * DT)[0]
    np.testing.assert_allclose(one[[0, 1, 4, 7]], [1.0, -1.0, 1.0, 1.0], rtol=1e-6)
    silent = gain_agc(np.zeros((2, 8)), DT, window_s=3 * DT)
    assert silent.dtype == np.float32 and np.array_equal(silent, np.zeros((2, 8)))


def test_agc_equalises_rms():
    t = np.arange(2000) * DT
    carrier = np.sin(2 * np.pi * 1e9 * t)
    x = (carrier * np.exp(-t / 40e-9))[None, :]
    out = gain_agc(x, DT, window_s=5e-9)[0]
    rms = [np.sqrt(np.mean(out[a : a + 100] ** 2)) for a in (100, 800, 1500)]
    np.testing.assert_allclose(rms, 1.0, rtol=0.1)


@pytest.mark.parametrize("f", [300e6, 500e6, 800e6])
def test_bandpass_passes_in_band_sinusoids_with_zero_phase(f):
    t = np.arange(4000) * DT
    x = np.cos(2 * np.pi * f * t)[None, :]
    y = bandpass(x, DT, fmin_hz=150e6, fmax_hz=1.5e9)[0]
    mid = slice(1000, 3000)
    assert np.max(np.abs(y[mid] - x[0, mid])) < 0.02  # gain ~1 and no phase shift


def test_bandpass_stops_out_of_band_and_matches_ba_design():
    t = np.arange(4000) * DT
    x = np.cos(2 * np.pi * 30e6 * t)[None, :] + np.cos(2 * np.pi * 3e9 * t)[None, :]
    y = bandpass(x, DT, fmin_hz=200e6, fmax_hz=1e9)[0]
    assert np.max(np.abs(y[1000:3000])) < 0.01
    # same Butterworth design through scipy's transfer-function (b, a) filtfilt
    b, a = signal.butter(4, [200e6, 1e9], btype="bandpass", fs=1 / DT)
    ref = signal.filtfilt(b, a, x[0], padtype="odd", padlen=3 * (max(len(a), len(b)) - 1))
    np.testing.assert_allclose(y[200:-200], ref[200:-200], atol=1e-3)


def test_bandpass_argument_errors():
    x = np.zeros((1, 100))
    with pytest.raises(ValueError, match="Nyquist"):
        bandpass(x, DT, fmin_hz=1e6, fmax_hz=6e9)
    with pytest.raises(ValueError, match="below"):
        bandpass(x, DT, fmin_hz=5e8, fmax_hz=1e8)


def test_envelope_of_an_amplitude_modulated_carrier():
    t = np.arange(4096) * DT
    a = 1.0 + 0.5 * np.sin(2 * np.pi * 5e6 * t)
    x = (a * np.cos(2 * np.pi * 1e9 * t))[None, :]
    np.testing.assert_allclose(envelope(x)[0, 200:-200], a[200:-200], atol=2e-3)
    assert envelope(x).dtype == np.float32


def test_resample_to_constant_spacing_is_exact_for_linear_data():
    # irregular spacing and the antenna standing still for three traces
    s = np.array([0.0, 0.013, 0.013, 0.013, 0.031, 0.050, 0.071, 0.09, 0.12])
    pos = np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1)
    data = np.outer(s, np.ones(8)).astype(np.float32)  # each trace holds its own distance
    out, s_new, src = resample_traces(data, pos, 0.02)
    np.testing.assert_allclose(s_new, np.arange(0, 0.12 + 1e-9, 0.02))
    np.testing.assert_allclose(out[:, 0], s_new, atol=1e-6)
    with pytest.raises(ValueError, match="^the path is 0.12 m long, shorter than one spacing of 1 m$"):
        resample_traces(data, pos, 1.0)
    assert out.dtype == np.float32 and src.dtype == np.float64
    # the fractional source index: new trace k between the kept traces around s = 0.02 k (trace 1 stands for the
    # standing run 1-3, so 0.02 m lies 7/18 of the way from index 1 to index 4)
    np.testing.assert_allclose(src[[0, 1, 3]], [0.0, 1 + 3 * (0.02 - 0.013) / (0.031 - 0.013),
                                                5 + (0.06 - 0.05) / 0.021], atol=1e-6)


def test_resample_standing_still_and_limits():
    """Steps of at most spacing / 100 (default) or min_step_m are standing still: the first of the run is kept;
    which traces are kept decides where the new traces between them come from. A path exactly one spacing long
    gives two traces; a spacing must be positive."""
    pos = np.zeros((4, 3))
    pos[:, 0] = [0.0, 0.005, 0.6, 1.1]  # the 5 mm step is spacing / 100 for a 0.5 m spacing: standing still
    data = np.arange(4, dtype=np.float32)[:, None] * np.ones((1, 4), np.float32)
    _, s_new, src = resample_traces(data, pos, 0.5)
    np.testing.assert_allclose(s_new, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(src[1], 2 * 0.5 / 0.6, atol=1e-6)  # merged: from traces 0 and 2
    _, _, src = resample_traces(data, pos, 0.5, min_step_m=0.001)  # 5 mm is a step now
    np.testing.assert_allclose(src[1], 1 + (0.5 - 0.005) / 0.595, atol=1e-6)
    _, _, src = resample_traces(data, pos, 0.25)  # default 2.5 mm: the 5 mm step counts
    np.testing.assert_allclose(src[1], 1 + (0.25 - 0.005) / 0.595, atol=1e-6)
    _, _, src = resample_traces(data, pos, 0.25, min_step_m=0.005)  # exactly the step: standing
    np.testing.assert_allclose(src[1], 2 * 0.25 / 0.6, atol=1e-6)
    line = np.c_[[0.0, 0.25, 0.5], np.zeros(3), np.zeros(3)]
    out, s_new, _ = resample_traces(np.ones((3, 4)), line, 0.5)
    np.testing.assert_allclose(s_new, [0.0, 0.5])
    for bad in (0.0, -1.0):
        with pytest.raises(ValueError, match=f"^spacing_m must be > 0, got {bad}$"):
            resample_traces(np.ones((3, 4)), line, bad)


@pytest.mark.parametrize("f_hz, dt_s, corners", [
    (400e6, 0.09375e-9, (160e6, 800e6)),  # 2 f below 0.9 Nyquist
    (3e9, 0.1e-9, (1.2e9, 4.5e9)),  # 2 f above it: the upper corner is 0.45 / dt
])
def test_bandpass_default_corners(f_hz, dt_s, corners):
    """Without corners, the band-pass step runs 0.4 f to min(2 f, 0.9 Nyquist): the recorded corners and the data
    against scipy's Butterworth with those corners."""
    from scipy.signal import butter, sosfiltfilt

    from gpr3d import Survey

    rng = np.random.default_rng(3)
    s = Survey(data=rng.standard_normal((4, 512)).astype(np.float32), dt_s=dt_s, frequency_hz=f_hz)
    out = s.bandpass()
    assert (out.history[-1]["result"]["fmin_hz"], out.history[-1]["result"]["fmax_hz"]) == pytest.approx(corners)
    sos = butter(4, list(corners), btype="bandpass", fs=1 / dt_s, output="sos")
    np.testing.assert_allclose(out.data, sosfiltfilt(sos, s.data.astype(float), axis=1), atol=1e-5)


def test_butterworth_kinds_against_scipy():
    """Band-pass (default order 4), high-pass (fmin only) and low-pass (fmax only): scipy's zero-phase Butterworth
    with the same corners; float32 out."""
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng(4)
    x = rng.standard_normal((3, 400)).astype(np.float32)
    fs = 1 / DT
    for kw, args in (({"fmin_hz": 2e8, "fmax_hz": 1.5e9}, ([2e8, 1.5e9], "bandpass")),
                     ({"fmin_hz": 3e8}, (3e8, "highpass")), ({"fmax_hz": 1e9}, (1e9, "lowpass"))):
        got = bandpass(x, DT, **kw)
        assert got.dtype == np.float32
        want = sosfiltfilt(butter(4, args[0], btype=args[1], fs=fs, output="sos"), x.astype(float), axis=1)
        np.testing.assert_allclose(got, want, atol=2e-5)
    got6 = bandpass(x, DT, fmax_hz=1e9, order=6)
    np.testing.assert_allclose(got6, sosfiltfilt(butter(6, 1e9, btype="lowpass", fs=fs, output="sos"), x.astype(float),
                                                 axis=1), atol=2e-5)


@pytest.mark.parametrize("kw, words", [
    ({}, "^give fmin_hz, fmax_hz or both$"),
    ({"fmin_hz": 0.0}, "fmin_hz = 0 Hz must lie between the lowest frequency"),
    ({"fmin_hz": 5e9}, "fmin_hz = 5e\\+09 Hz must lie between .* and the Nyquist frequency 5e\\+09"),
    ({"fmax_hz": 5e9}, "fmax_hz = 5e\\+09 Hz"),
    ({"fmin_hz": 1e9, "fmax_hz": 1e9}, "fmin_hz \\(1e\\+09\\) must be below fmax_hz"),
])
def test_bandpass_refuses_corners_it_cannot_use(kw, words):
    with pytest.raises(ValueError, match=words):
        bandpass(np.zeros((2, 400), np.float32), DT, **kw)


def test_corners_below_what_the_trace_holds_are_refused():
    """400 samples of 0.1 ns hold nothing below 1 / 40 ns = 25 MHz: a corner there (e.g. 0.5: MHz given as Hz)
    is refused in one line, 25 MHz itself is taken."""
    from scipy.signal import butter, sosfiltfilt

    x = np.random.default_rng(6).standard_normal((2, 400))
    with pytest.raises(ValueError, match=r"fmin_hz = 0.5 Hz must lie between the lowest frequency the 400-sample "
                                         r"traces hold \(2.5e\+07 Hz\)"):
        bandpass(x, DT, fmin_hz=0.5)
    with pytest.raises(ValueError, match=r"fmax_hz = 2.49e\+07 Hz"):
        bandpass(x, DT, fmax_hz=2.49e7)
    sos = butter(4, 2.5e7, btype="highpass", fs=1 / DT, output="sos")
    np.testing.assert_allclose(bandpass(x, DT, fmin_hz=2.5e7), sosfiltfilt(sos, x, axis=1), atol=2e-5)


def test_bandpass_needs_traces_longer_than_its_padding():
    """scipy pads 3 (2 sections + 1) samples at each end: an order-4 band-pass (4 sections) needs more than 27."""
    from scipy.signal import butter, sosfiltfilt

    with pytest.raises(ValueError, match="traces of 27 samples are too short for an order-4 filter"):
        bandpass(np.ones((2, 27), np.float32), DT, fmin_hz=4e8, fmax_hz=1.5e9)
    x = np.random.default_rng(5).standard_normal((2, 28))
    sos = butter(4, [4e8, 1.5e9], btype="bandpass", fs=1 / DT, output="sos")
    np.testing.assert_allclose(bandpass(x, DT, fmin_hz=4e8, fmax_hz=1.5e9), sosfiltfilt(sos, x, axis=1), atol=2e-5)


def _trailing_by_hand(x, w, stat):
    """Each trace less ``stat`` of itself and the ``w - 1`` traces before it, the first trace standing in for
    those before the survey."""
    pad = np.concatenate([np.repeat(x[:1], w - 1, axis=0), x])
    return np.stack([x[i] - stat(pad[i:i + w], axis=0) for i in range(len(x))])


@pytest.mark.parametrize("w", [2, 3, 4, 7, 21])  # (21: longer than the survey, still trailing, not its mean)
def test_a_trailing_background_window_ends_at_each_trace(w):
    x = np.random.default_rng(3).normal(size=(15, 4)).astype(np.float32)
    np.testing.assert_allclose(remove_background(x, window_traces=w, trailing=True),
                               _trailing_by_hand(x, w, np.mean), atol=1e-6)
    if w % 2:  # (an even window's median is scipy's upper middle value, not numpy's mean of the two)
        np.testing.assert_allclose(remove_background(x, method="median", window_traces=w, trailing=True),
                                   _trailing_by_hand(x, w, np.median), atol=1e-6)
    # trace i's background uses no trace after it: changing the later traces leaves it as it was
    y = x.copy()
    y[9:] += 5.0
    np.testing.assert_array_equal(remove_background(y, window_traces=w, trailing=True)[:9],
                                  remove_background(x, window_traces=w, trailing=True)[:9])


def test_a_moving_background_is_named_when_wrong():
    x = np.zeros((4, 3), np.float32)
    with pytest.raises(ValueError, match="window_traces must be >= 2"):
        moving_background(x, 1)
    with pytest.raises(ValueError, match="unknown background method 'mode'"):
        moving_background(x, 3, method="mode")


def test_a_moving_background_by_default_is_the_centred_mean_in_double_precision():
    x = (1e4 + np.random.default_rng(5).normal(size=(9, 2))).astype(np.float32)
    got = moving_background(x, 3)
    pad = np.concatenate([x[:1], x, x[-1:]]).astype(np.float64)
    np.testing.assert_allclose(got, (pad[:-2] + pad[1:-1] + pad[2:]) / 3, rtol=0, atol=1e-9)
    assert got.dtype == np.float64
