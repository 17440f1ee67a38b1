import numpy as np
import pytest

import gpr3d
from gpr3d.processing import direct_wave_peak, estimate_time_zero, first_break, shift_traces
from gpr3d.simulation.synthetic import point_targets_bscan, ricker

DT = 0.05e-9


def test_peak_of_a_ricker_at_a_fractional_time():
    t = np.arange(400) * DT
    t_true = 3.4321e-9
    x = np.stack([ricker(t - t_true - k * 0.011e-9, 1e9) for k in range(5)])
    idx = direct_wave_peak(x)
    np.testing.assert_allclose(idx * DT, t_true + 0.011e-9 * np.arange(5), atol=0.004e-9)
    assert estimate_time_zero(x, DT, method="peak") == pytest.approx(t_true + 0.022e-9, abs=0.004e-9)


def test_first_break_on_a_ramp():
    x = np.zeros((1, 100))
    x[0, 40:60] = np.arange(20) / 19  # reaches 0.1 between samples 41 and 42
    assert first_break(x, 0.1)[0] == pytest.approx(40 + 0.1 * 19)


def test_shift_traces_matches_interpolation():
    rng = np.random.default_rng(2)
    x = rng.standard_normal((4, 50)).astype(np.float32)
    shifts = np.array([0.0, 1.5, 3.25, 2.0])
    y = shift_traces(x, shifts)
    assert y.shape == (4, 50 - 4)  # floor(49 - 3.25) + 1
    for i in range(4):
        ref = np.interp(np.arange(y.shape[1]) + shifts[i], np.arange(50), x[i])
        np.testing.assert_allclose(y[i], ref, atol=1e-6)


@pytest.mark.parametrize("shift", [0.0, 3.25, 7.9, 10.0])
def test_one_shift_for_all_traces_matches_interpolation(shift):
    """The uniform-shift path (two slices) gives np.interp's values, the same as the per-trace path."""
    rng = np.random.default_rng(5)
    x = rng.standard_normal((6, 40)).astype(np.float32)
    y = shift_traces(x, shift)
    assert y.shape == (6, int(np.floor(39 - shift + 1e-9)) + 1)
    for i in range(6):
        ref = np.interp(np.arange(y.shape[1]) + shift, np.arange(40), x[i])
        np.testing.assert_allclose(y[i], ref, atol=1e-6)
    per_trace = shift_traces(x, np.array([shift] * 5 + [shift + 1e-12]))  # (not all equal: the general path)
    np.testing.assert_allclose(y, per_trace[:, : y.shape[1]], atol=1e-5)


def test_time_zero_step_on_synthetic_survey():
    s = point_targets_bscan([[0.3, 0.2]], t0_s=2e-9, offset_m=0.0, dt_s=DT, n_samples=300)
    p = s.time_zero(method="peak", search_s=4e-9)
    assert p.history[-1]["result"]["t0_s"] == pytest.approx(2e-9, abs=0.01e-9)
    assert p.t0_s == 0.0 and p.n_samples < s.n_samples
    q = s.time_zero(method="peak", search_s=4e-9, shift=False)
    assert q.t0_s == pytest.approx(2e-9, abs=0.01e-9) and q.n_samples == s.n_samples
    with pytest.raises(gpr3d.InvalidDataError, match="time_zero: method must be 'first_break' or 'peak', got 'guess'"):
        s.time_zero(method="guess")


def test_time_zero_takes_off_the_direct_waves_offset():
    # the direct wave peaks offset/c after the pulse leaves; the estimate must land on the departure
    s = point_targets_bscan([[0.3, 0.2]], t0_s=2e-9, offset_m=0.3, dt_s=DT, n_samples=300)
    p = s.time_zero(method="peak", search_s=4e-9, shift=False)
    assert p.t0_s == pytest.approx(2e-9, abs=0.01e-9)
    q = s.time_zero(method="peak", search_s=4e-9, shift=False, offset_correction=False)
    assert q.t0_s - p.t0_s == pytest.approx(0.3 / 299792458.0, rel=1e-9, abs=0)


def test_peak_time_zero_is_not_taken_by_a_shallow_echo_stronger_than_the_direct_wave():
    """A rebar mat under a few cm of cover outshines the direct wave in most traces (here 70 %, echo 1.6x, at a
    time that moves from trace to trace). Time zero stays on the direct wave: the mean trace's peak (the median of
    per-trace peaks, as before, lands on the echoes)."""
    rng = np.random.default_rng(3)
    t = np.arange(400) * DT
    t_direct = 2.0e-9
    x = np.stack([ricker(t - t_direct, 1e9) for _ in range(50)])
    for i in rng.permutation(50)[:35]:
        x[i] += 1.6 * ricker(t - (3.3e-9 + rng.uniform(-0.2e-9, 0.2e-9)), 1e9)
    assert np.median(direct_wave_peak(x)) * DT > 3.0e-9  # most traces' largest peak is the echo
    assert estimate_time_zero(x, DT, method="peak") == pytest.approx(t_direct, abs=0.01e-9)
    # per trace, rel=0.5 finds the first peak at least half the largest: the direct wave
    np.testing.assert_allclose(direct_wave_peak(x, rel=0.5) * DT, t_direct, atol=0.01e-9)
    with pytest.raises(ValueError, match="rel"):
        direct_wave_peak(x, rel=0.0)


def test_first_break_by_hand():
    """First sample at 0.1 (default) of the trace's largest |amplitude|, interpolated on the rising edge; a trace
    that starts above the level is at 0; one that reaches it at sample 1 interpolates from sample 0."""
    x = np.array([[0.0, 0.1, 0.4, -2.0, 0.3, 0.7],   # level 0.2: between 0.1 and 0.4 -> 1 + 1/3
                  [2.0, 0.5, 0.3, 0.0, 0.0, 0.9],    # already above at sample 0 (the last sample is not "before")
                  [0.0, 1.0, 0.0, 0.0, 0.0, 0.0]])   # level 0.1 reached at sample 1: 0 + 0.1
    np.testing.assert_allclose(first_break(x), [1 + 1 / 3, 0.0, 0.1])
    np.testing.assert_allclose(first_break(x, 1.0), [3.0, 0.0, 1.0])  # the maximum itself
    for bad in (0.0, 1.5):
        with pytest.raises(ValueError, match=rf"^threshold must be in \(0, 1\], got {bad}$"):
            first_break(x, bad)


def test_direct_wave_peak_by_hand():
    """The first local maximum of |amplitude| reaching rel x the largest, refined by the parabola through it and
    its neighbours; ends count as peaks (no refinement); the search window cuts the trace."""
    x = np.array([[0.0, 1.0, 3.0, 2.0, 0.0, 5.0, 0.0],  # rel 1: sample 5 (y 0, 5, 0: no shift)
                  [5.0, 3.0, 4.0, 0.0, 0.0, 0.0, 0.0],  # the first sample is the peak
                  [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]])  # rising to the last sample
    np.testing.assert_allclose(direct_wave_peak(x), [5.0, 0.0, 6.0])
    # rel 0.5: row 0 stops at sample 2 (3 >= 2.5): vertex of (1, 3, 2) = 2 + 0.5 (1 - 2) / (1 - 6 + 2) = 2 + 1/6
    np.testing.assert_allclose(direct_wave_peak(x, rel=0.5)[:2], [2 + 1 / 6, 0.0])
    # the search window: 3 samples (the least) of row 0 -> the rising edge ends at sample 2
    np.testing.assert_allclose(direct_wave_peak(x, 3)[0], 2.0)
    np.testing.assert_allclose(direct_wave_peak(x, 1)[0], 2.0)  # fewer than 3 asked: 3 searched
    # peaks at sample 1 and at the second-to-last sample are refined too
    y = np.array([[1.0, 4.0, 2.0, 0.0, 0.0], [0.0, 0.0, 1.0, 4.0, 2.0]])
    np.testing.assert_allclose(direct_wave_peak(y), [1 + 0.5 * (1 - 2) / (1 - 8 + 2), 3 + 0.5 * (1 - 2) / (1 - 8 + 2)])
    # a flat top of three samples: the first of them, refined towards the rise (not the last, refined back)
    np.testing.assert_allclose(direct_wave_peak(np.array([[0.0, 2.0, 2.0, 2.0, 0.0]])), [1.5])
    with pytest.raises(ValueError, match=r"^rel must be in \(0, 1\], got 1.5$"):
        direct_wave_peak(x, rel=1.5)


def test_estimate_time_zero_options_by_hand():
    dt = 1e-9
    x = np.zeros((3, 40))
    x[:, 10] = 1.0  # the direct wave at 10 ns in every trace
    x[:, 9] = x[:, 11] = 0.5
    x[0, 25] = 3.0  # a strong late echo in one trace
    assert estimate_time_zero(x, dt) == pytest.approx(np.median(first_break(x)) * dt, rel=1e-9, abs=0)  # first break, 0.1
    assert estimate_time_zero(x, dt, threshold=0.5) == pytest.approx(np.median(first_break(x, 0.5)) * dt, rel=1e-9, abs=0)
    # the mean trace peaks on the echo (3 / 3 = 1 ties the direct wave: the first wins), per trace row 0 does not
    # without a search window, and does with one of 15 ns
    assert estimate_time_zero(x, dt, method="peak") == pytest.approx(10e-9, rel=1e-9, abs=0)
    per = estimate_time_zero(x, dt, method="peak", per_trace=True)
    np.testing.assert_allclose(per, [25e-9, 10e-9, 10e-9])
    np.testing.assert_allclose(estimate_time_zero(x, dt, method="peak", per_trace=True, search_s=15e-9), 10e-9)
    x[1:, 25] = 3.0  # now the echo outshines the direct wave in the mean trace too
    assert estimate_time_zero(x, dt, method="peak") == pytest.approx(25e-9, rel=1e-9, abs=0)
    assert estimate_time_zero(x, dt, method="peak", search_s=15e-9) == pytest.approx(10e-9, rel=1e-9, abs=0)
    with pytest.raises(ValueError, match=r"^unknown time-zero method 'max' \(use 'first_break' or 'peak'\)$"):
        estimate_time_zero(x, dt, method="max")


def test_shift_traces_limits_and_types():
    x = np.arange(20, dtype=np.float64).reshape(2, 10)
    out = shift_traces(x, 8.0)  # exactly two samples left
    assert out.dtype == np.float32 and out.shape == (2, 2)
    np.testing.assert_allclose(out, x[:, 8:])
    general = shift_traces(x, [8.0, 7.5])
    assert general.dtype == np.float32
    np.testing.assert_allclose(general, [[8.0, 9.0], [17.5, 18.5]])
    one = shift_traces(x[:1], 2.25)  # a single trace
    np.testing.assert_allclose(one, [np.arange(2.25, 9.0, 1.0)])
    with pytest.raises(ValueError, match=r"^time zero is at the end of the traces: nothing left after cutting$"):
        shift_traces(x, 8.5)
    with pytest.raises(ValueError, match=r"^shifts must be >= 0 \(time zero lies after the first sample\)$"):
        shift_traces(x, [1.0, -0.5])
