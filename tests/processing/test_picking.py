"""pick_peak: the largest value near a guess, refined by a parabola (checked against the parabola's own vertex)."""

import math

import numpy as np
import pytest

from gpr3d.processing.picking import pick_peak

DT = 0.1e-9


def test_a_parabola_is_picked_at_its_vertex_with_its_height():
    t = np.arange(100) * DT
    row = 2.0 - 1e18 * (t - 4.37e-9) ** 2  # vertex 4.37 ns, height 2
    data = np.stack([np.zeros(100), row])
    tp, v = pick_peak(data, DT, 1, 4.2e-9, 1e-9)
    assert tp == pytest.approx(4.37e-9, abs=1e-15) and v == pytest.approx(2.0, abs=1e-9)


def test_only_the_window_counts_and_its_edges_are_included():
    row = np.zeros(50)
    row[10], row[30] = 5.0, 9.0  # the larger one lies outside the window around sample 10
    row[[9, 11]] = [1.0, 3.0]
    tp, v = pick_peak(row[None], DT, 0, 10 * DT, 3 * DT)
    d = 0.5 * (1.0 - 3.0) / (1.0 - 10.0 + 3.0)
    assert tp == pytest.approx((10 + d) * DT, rel=1e-9, abs=0) and v == pytest.approx(5.0 - 0.25 * (1.0 - 3.0) * d, rel=1e-9, abs=0)
    # the window 27..33 samples reaches the 9 at 30
    assert pick_peak(row[None], DT, 0, 30 * DT, 3 * DT)[1] == pytest.approx(9.0)
    # a window ending exactly on sample 30 includes it
    assert pick_peak(row[None], DT, 0, 28 * DT, 2 * DT)[1] == pytest.approx(9.0)


def test_ends_and_flat_tops_are_not_refined():
    row = np.array([4.0, 1.0, 0.0, 0.0, 2.0, 2.0, 0.0, 0.0, 1.0, 6.0])
    assert pick_peak(row[None], DT, 0, 0.0, 1.5 * DT) == (0.0, 4.0)  # first sample
    assert pick_peak(row[None], DT, 0, 9 * DT, 1.5 * DT) == (pytest.approx(9 * DT, rel=1e-9, abs=0), 6.0)  # last sample
    # a flat top: the window's first maximum is sample 2, between equal neighbours: no curvature, no refinement
    tp, v = pick_peak(np.array([[0.0, 3.0, 3.0, 3.0, 0.0]]), 1.0, 0, 2.5, 0.5)
    assert (tp, v) == (2.0, 3.0)


def test_a_window_outside_the_record_gives_nan():
    row = np.arange(10.0)
    for guess in (20 * DT, -5 * DT):
        tp, v = pick_peak(row[None], DT, 0, guess, 1 * DT)
        assert math.isnan(tp) and math.isnan(v)


def test_window_bounds_in_samples():
    """dt = 1: the window floor(guess - half) .. ceil(guess + half), clipped to the record; a window that keeps
    one sample or none gives nan; a larger value just past the window is not seen."""
    row = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 5.0, 0.0, 1.0, 9.0, 0.0])
    assert pick_peak(row[None], 1.0, 0, 10.0, 2.0)[1] == pytest.approx(5.0)  # 8..12: the 9 at 13 is out
    tp, _ = pick_peak(row[None], 1.0, 0, 1.5, 1.0)  # 0..3: the peak at sample 1, refined (0, 1, 0: no shift)
    assert tp == pytest.approx(1.0)
    r2 = np.array([0.0, 4.0, 1.0, 0.0, 0.0, 2.0, 7.0, 3.0])
    d1 = 0.5 * (0.0 - 1.0) / (0.0 - 8.0 + 1.0)
    assert pick_peak(r2[None], 1.0, 0, 1.0, 1.0)[0] == pytest.approx(1 + d1)  # sample 1 is refined
    d6 = 0.5 * (2.0 - 3.0) / (2.0 - 14.0 + 3.0)
    assert pick_peak(r2[None], 1.0, 0, 6.0, 1.0)[0] == pytest.approx(6 + d6)  # so is the second-to-last
    for guess in (15.5, 16.0):  # one sample (14) or none left in the window
        assert all(math.isnan(v) for v in pick_peak(row[None], 1.0, 0, guess, 1.0)), guess
