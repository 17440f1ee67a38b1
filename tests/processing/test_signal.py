"""signal_end: where neighbouring traces stop looking alike. Checked on records whose answer is known by
construction (a coherent event that ends at a chosen sample, then noise alone), against coherences computed here
by hand, and on the real recordings where the folder is present."""

import math
from pathlib import Path

import numpy as np
import pytest

from gpr3d.processing import signal as S

DT = 0.1e-9
F = 500e6  # a window: 2 periods = 4 ns = 40 samples
W = 40
SIX_SIGMA = 6 / math.sqrt(48 * W)  # noise's spread in a run of 48 pairs: 0.137, above the 0.1 floor


def _ricker(t, f):
    a = (np.pi * f * t) ** 2
    return (1 - 2 * a) * np.exp(-a)


def _record(n_traces=400, n=600, last_event_s=25e-9, noise=0.05, seed=0, traces=None):
    """Point diffractions every 2 ns down to ``last_event_s`` (apexes 0.3 m apart along the line, hyperbolas of
    0.1 m/ns fading over 0.15 m as a beam's edge), and white noise of ``noise`` x the events' peak everywhere;
    ``traces``: the events only in those."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    x = np.arange(n_traces) * 0.01
    data = np.zeros((n_traces, n))
    rows = np.arange(n_traces) if traces is None else np.asarray(traces)
    for k, t0 in enumerate(np.arange(3e-9, last_event_s + 1e-12, 2e-9)):
        apex = x[rows[0]] + (0.3 * k) % max(x[rows[-1]] - x[rows[0]], 0.3)
        tt = np.sqrt(t0 ** 2 + (2 * (x[rows] - apex) / 0.1e9) ** 2)
        data[rows] += _ricker(t[None, :] - tt[:, None], F) * np.exp(-(((x[rows] - apex) / 0.15) ** 2))[:, None]
    return data + noise * rng.standard_normal(data.shape)


def test_window_coherence_by_hand():
    data = np.array([[1.0, 2.0, 0.0, 1.0, 3.0],
                     [1.0, 2.0, 0.0, -1.0, 0.0],
                     [2.0, 0.0, 0.0, 0.0, 0.0]])
    # windows of 2: [0, 2), [2, 4), [4, 5) padded
    a, b = data[:-1], data[1:]
    want = []
    for lo, hi in ((0, 2), (2, 4), (4, 5)):
        cross = (a[:, lo:hi] * b[:, lo:hi]).sum()
        power = ((a[:, lo:hi] ** 2).sum() + (b[:, lo:hi] ** 2).sum()) / 2
        want.append(cross / power if power else 0.0)
    assert np.allclose(S.window_coherence(data, 2), want)
    # runs of one trace pair each (two runs: the pairs (0, 1) and (1, 2))
    by_run = S.window_coherence(data, 2, block=1)
    assert by_run.shape == (2, 3)
    assert by_run[0, 0] == pytest.approx((1 + 4) / ((1 + 4 + 1 + 4) / 2))
    assert by_run[1, 0] == pytest.approx(2 / ((1 + 4 + 4) / 2))
    assert by_run[0, 1] == pytest.approx(-1 / 1) and by_run[1, 2] == 0.0  # (nothing there: 0)


def test_the_signal_ends_a_margin_after_the_last_coherent_window():
    data = _record(last_event_s=25e-9)
    end = S.signal_end(data, DT, F)
    assert end.window_samples == W
    # the last event's wavelet reaches ~25 ns + 1 period (window 6, 24-28 ns); its tail a window further at most;
    # the three-window average lifts one more; then the margin
    assert end.end_s is not None
    last = end.end_s / DT / W - S.MARGIN_WINDOWS  # one past the last window taken for signal
    assert 7 <= last <= 9, end
    assert end.threshold == pytest.approx(max(S.MIN_COHERENCE, S.NOISE_SIGMAS / math.sqrt(S.BLOCK_TRACES * W)))
    assert end.reason == f"no signal above the noise after {end.end_s * 1e9:.1f} ns (coherence of neighbouring " \
                         f"traces <= {end.threshold:.2f})"
    # after the events every run's coherence is noise's (about 0); during them the runs under an apex are near 1
    assert end.coherence.shape == (8, 15)  # 399 pairs in runs of 48 (the last takes the rest), 600 / 40 windows
    assert np.all(np.abs(end.coherence[:, 9:]) < 0.1) and (end.coherence[:, 1:6].max(axis=1) > 0.8).sum() >= 6
    # a later last event moves the end by as much
    later = S.signal_end(_record(last_event_s=37e-9), DT, F)
    assert later.end_s - end.end_s == pytest.approx(12e-9, abs=W * DT)


def test_a_time_varying_gain_does_not_move_the_end():
    data = _record()
    ramp = 1 + (np.arange(data.shape[1]) * DT / 1e-9) ** 2  # the late noise ~3600 x louder, as a radar's range gain
    assert S.signal_end(data * ramp, DT, F).end_s == S.signal_end(data, DT, F).end_s


def test_a_target_few_traces_see_is_not_diluted_by_the_rest():
    # 3000 traces; a deep event (to 40 ns) only in 60 of them, shallow ones everywhere (to 15 ns)
    shallow = _record(n_traces=3000, last_event_s=15e-9, noise=0.05)
    deep = 0.1 * _record(n_traces=3000, last_event_s=40e-9, noise=0.0, traces=np.arange(1500, 1560))
    deep[:, : int(16e-9 / DT)] = 0.0  # (the deep record's shallow events are there already)
    end = S.signal_end(shallow + deep, DT, F)
    assert end.end_s is not None and end.end_s >= 40e-9, end
    pooled = S.window_coherence(shallow + deep, W)  # all traces pooled: the deep event drowns
    assert pooled[int(30e-9 / DT / W)] < S.MIN_COHERENCE


def test_records_that_are_not_cut():
    rng = np.random.default_rng(3)
    noise = S.signal_end(rng.standard_normal((400, 600)), DT, F)
    assert noise.end_s is None and noise.reason == "no window of the record stands above the noise"
    to_the_end = S.signal_end(_record(last_event_s=58e-9), DT, F)
    assert to_the_end.end_s is None and to_the_end.reason == "the signal reaches the record's end"
    few = S.signal_end(_record(n_traces=S.MIN_TRACES - 1), DT, F)
    assert few.end_s is None and few.reason == f"{S.MIN_TRACES - 1} traces of 600 samples are too few to tell " \
                                                "signal from noise"
    # (exactly MIN_TRACES: judged)
    assert S.signal_end(_record(n_traces=S.MIN_TRACES), DT, F).end_s is not None


@pytest.mark.parametrize("args, msg", [
    ((np.zeros(10), DT, F), r"data must be \(n_traces, n_samples\), got shape \(10,\)"),
    ((np.zeros((30, 200)), 0.0, F), "dt_s and frequency_hz must be positive, got 0.0 and"),
    ((np.zeros((30, 200)), DT, float("nan")), "dt_s and frequency_hz must be positive"),
    ((np.zeros((30, 200)), DT, float("inf")), "dt_s and frequency_hz must be positive"),
    ((np.zeros((30, 200)), DT, 0.0), "dt_s and frequency_hz must be positive"),
    ((np.zeros((30, 200)), float("inf"), F), "dt_s and frequency_hz must be positive"),
    ((np.zeros((30, 200)), -DT, F), "dt_s and frequency_hz must be positive"),
])
def test_wrong_arguments_are_named(args, msg):
    with pytest.raises(ValueError, match=msg):
        S.signal_end(*args)


REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"


@pytest.mark.skipif(not (REAL / "gpro_sns_100MHz_grid").is_dir(), reason="the real recordings are not here")
def test_real_recordings_noise_after_the_signal_and_correlated_noise_to_the_end():
    from gpr3d.io import read
    from gpr3d.migration.refine import dominant_frequency_hz

    def end_of(path):
        s = read(path).time_zero(method="peak", search_s=10e-9 if "100MHz" not in str(path) else 40e-9)
        s = s.remove_background()
        return S.signal_end(s.data, s.dt_s, dominant_frequency_hz(s.data, s.dt_s)), s

    # Sensors & Software 100 MHz grid line: reflections to about 2/3 of the record, then noise (r ~ 0)
    end, s = end_of(REAL / "gpro_sns_100MHz_grid" / "XLINE00.DT1")
    assert end.end_s is not None and 0.5 < end.end_s / (s.n_samples * s.dt_s) < 0.8, end
    # the 50 MHz line's noise is alike from trace to trace (r ~ 0.65 to the end): not cut
    end, _ = end_of(REAL / "gprpy_sns_50MHz" / "XLINE00.DT1")
    assert end.end_s is None and end.reason == "the signal reaches the record's end"


def test_runs_of_trace_pairs_by_hand():
    # 8 traces (7 pairs) of 2 samples, runs of 3 pairs: pairs 0-2 and 3-6 (the last run takes the short remainder)
    data = np.array([[1, 2], [1, 2], [1, 2], [2, -1], [1, 0], [1, 0], [0, 0], [0, 0]], float)
    got = S.window_coherence(data, 2, block=3)
    a, b = data[:-1], data[1:]

    def r(pairs):
        c = (a[pairs] * b[pairs]).sum()
        p = ((a[pairs] ** 2).sum() + (b[pairs] ** 2).sum()) / 2
        return c / p

    np.testing.assert_allclose(got, [[r(slice(0, 3))], [r(slice(3, 7))]], rtol=1e-6)
    assert got.shape == (2, 1)
    # 6 pairs in runs of 2: three runs, however few samples the traces have
    assert S.window_coherence(np.ones((7, 3)), 4, block=2).shape == (3, 1)
    # fewer pairs than a run: one run, pooled over all
    np.testing.assert_allclose(S.window_coherence(data, 2, block=50), [S.window_coherence(data, 2)], rtol=1e-6)
    # no energy at all: 0
    assert S.window_coherence(np.zeros((3, 4)), 2).tolist() == [0.0, 0.0]


def _blocks(n_traces, n_windows, signal_windows, seed=0):
    """Traces alike (the same random wiggle in each) in ``signal_windows`` windows of W samples, independent noise
    elsewhere: coherence 1 there and about 0 elsewhere."""
    rng = np.random.default_rng(seed)
    data = rng.standard_normal((n_traces, n_windows * W))
    common = rng.standard_normal(n_windows * W)
    for k in signal_windows:
        data[:, k * W:(k + 1) * W] = common[k * W:(k + 1) * W]
    return data


def test_the_end_window_by_window():
    # alike in windows 0..5: the three-window average lifts window 6 (1/3), not 7; the margin adds two
    end = S.signal_end(_blocks(200, 15, range(6)), DT, F)
    assert end.end_s == pytest.approx((6 + 1 + S.MARGIN_WINDOWS) * W * DT)
    # the signal to window 11 of 15: the end would fall on the record's end exactly: not cut
    end = S.signal_end(_blocks(200, 15, range(12)), DT, F)
    assert end.end_s is None and end.reason == "the signal reaches the record's end"
    # ... to window 10: cut one window before it
    assert S.signal_end(_blocks(200, 15, range(11)), DT, F).end_s == pytest.approx(14 * W * DT)
    assert S.signal_end(_blocks(200, 15, range(6)), DT, F).to_dict() == {
        "end_s": pytest.approx(9 * W * DT), "window_samples": W, "threshold": pytest.approx(SIX_SIGMA),
        "reason": f"no signal above the noise after {9 * W * DT * 1e9:.1f} ns (coherence of neighbouring traces "
                  f"<= {SIX_SIGMA:.2f})"}


def test_the_threshold_of_one_run_counts_its_pairs():
    end = S.signal_end(_blocks(30, 15, range(3)), DT, F)  # 29 pairs in one run
    assert end.threshold == pytest.approx(S.NOISE_SIGMAS / math.sqrt(29 * W))  # 0.176, above MIN_COHERENCE
    assert end.coherence.shape == (1, 15)
    end = S.signal_end(_blocks(200, 15, range(3)), DT, F)  # runs of 48: 6 sigma = 0.137
    assert end.threshold == pytest.approx(SIX_SIGMA)
    assert end.coherence.shape == (4, 15)


def test_windows_and_the_shortest_record_judged():
    # a window is two periods, four samples at the least
    assert S.signal_end(_record(), DT, 2 / (3 * DT)).window_samples == 4
    assert S.signal_end(_record(), DT, 2 / (7 * DT)).window_samples == 7
    # three windows: judged; one sample fewer: too few
    judged = S.signal_end(_blocks(100, 3, range(1)), DT, F)
    assert "too few" not in judged.reason and judged.coherence.shape == (2, 3)  # (99 pairs: runs of 48 and 51)
    few = S.signal_end(_blocks(100, 3, range(1))[:, :-1], DT, F)
    assert few.reason == f"100 traces of {3 * W - 1} samples are too few to tell signal from noise"
    assert few.window_samples == W and math.isnan(few.threshold) and few.coherence.size == 0
    # a frequency so low that a window outlasts the record: too few, not an error
    assert S.signal_end(_record(), DT, 0.5).end_s is None
    noise = S.signal_end(np.random.default_rng(3).standard_normal((400, 600)), DT, F)
    assert noise.window_samples == W and noise.threshold == pytest.approx(SIX_SIGMA)
    assert noise.coherence.shape == (8, 15)
    whole = S.signal_end(_record(last_event_s=58e-9), DT, F)
    assert whole.window_samples == W and whole.threshold == pytest.approx(SIX_SIGMA)
    assert whole.coherence.shape == (8, 15)
