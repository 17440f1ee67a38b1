"""Processing against independent references: explicit convolutions, analytic signals, closed forms."""

import numpy as np
import pytest
from scipy import signal

from gpr3d.processing import (
    bandpass, dewow, envelope, gain_agc, gain_sec, gain_tpow, remove_background, remove_dc, resample_traces,
)

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


def test_gains_closed_form():
    x = np.ones((2, 100), dtype=np.float32)
    t = np.arange(100) * DT
    t0 = 2e-9
    tp = np.maximum(t - t0, 0)
    np.testing.assert_allclose(gain_tpow(x, DT, power=2, t0_s=t0)[0], np.maximum(tp / 1e-9, 1) ** 2, rtol=1e-6)
    g = gain_sec(x, DT, alpha_per_s=1e8, power=1, t0_s=t0, max_gain=None)[0]
    np.testing.assert_allclose(g, np.maximum(tp / 1e-9, 1) * np.exp(1e8 * tp), rtol=1e-6)
    assert gain_sec(x, DT, alpha_per_s=1e10, max_gain=50)[0].max() == pytest.approx(50)


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


def test_resample_to_constant_spacing_is_exact_for_linear_data():
    # irregular spacing and the antenna standing still for three traces
    s = np.array([0.0, 0.013, 0.013, 0.013, 0.031, 0.050, 0.071, 0.09, 0.12])
    pos = np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1)
    data = np.outer(s, np.ones(8)).astype(np.float32)  # each trace holds its own distance
    out, s_new, src = resample_traces(data, pos, 0.02)
    np.testing.assert_allclose(s_new, np.arange(0, 0.12 + 1e-9, 0.02))
    np.testing.assert_allclose(out[:, 0], s_new, atol=1e-6)
    with pytest.raises(ValueError, match="shorter than one spacing"):
        resample_traces(data, pos, 1.0)


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
