import numpy as np
import pytest
from scipy.signal import hilbert

from gpr3d import Survey
from gpr3d.core.errors import InvalidDataError
from gpr3d.io.volume import read_cscan, write_cscan
from gpr3d.processing.cscan import cscan
from gpr3d.simulation.synthetic import ricker

DT = 0.1e-9


def grid_survey(anomaly_xy=(0.6, 0.4), t_echo=12e-9):
    """Lines 0.2 m apart, traces every 0.05 m; a Ricker echo at ``t_echo`` under traces within 0.1 m of
    ``anomaly_xy``, weak noise elsewhere."""
    xs, ys = np.arange(0, 1.2001, 0.05), np.arange(0, 0.8001, 0.2)
    pos = np.array([(x, y, 0.0) for y in ys for x in xs])
    t = np.arange(300) * DT
    rng = np.random.default_rng(0)
    data = 0.01 * rng.standard_normal((len(pos), 300))
    near = np.hypot(pos[:, 0] - anomaly_xy[0], pos[:, 1] - anomaly_xy[1]) < 0.1
    data[near] += ricker(t - t_echo, 1e9)
    return Survey(data=data.astype(np.float32), dt_s=DT, positions_xyz=pos)


def test_a_buried_echo_lights_its_cell_in_its_slice():
    s = grid_survey()
    cs = cscan(s, cell_m=0.05, window_s=4e-9)
    k = int(np.argmax(np.nanmax(cs.values, axis=(1, 2))))
    assert cs.t_start_s[k] <= 12e-9 < cs.t_start_s[k] + 4e-9
    i, j = np.unravel_index(int(np.nanargmax(cs.values[k])), cs.values[k].shape)
    assert (cs.x[i], cs.y[j]) == (pytest.approx(0.6, abs=0.101), pytest.approx(0.4, abs=0.101))  # the echo's reach
    # a cell holding one trace is that trace's mean envelope over the window (independent: scipy's hilbert)
    tr = int(np.argmin(np.hypot(s.positions_xyz[:, 0] - 0.6, s.positions_xyz[:, 1] - 0.4)))
    env = np.abs(hilbert(s.data[tr].astype(float)))
    t = np.arange(s.n_samples) * DT
    want = env[(t >= cs.t_start_s[k]) & (t < cs.t_start_s[k] + 4e-9)].mean()
    ii, jj = np.rint((s.positions_xyz[tr, :2] - [cs.x0, cs.y0]) / 0.05).astype(int)
    assert cs.values[k, ii, jj] == pytest.approx(want, rel=1e-5)


def test_gaps_between_lines_fill_within_reach_and_stay_empty_beyond():
    s = grid_survey()
    near = cscan(s, cell_m=0.05, window_s=4e-9, fill_m=0.1)  # cells 0.05-0.1 m from a line get filled
    assert np.isfinite(near.values).all()
    none = cscan(s, cell_m=0.05, window_s=4e-9, fill_m=0.0)
    assert np.isnan(none.values[0, :, 1]).all() and np.isfinite(none.values[0, :, 0]).all()


def test_depth_labels_and_the_file_round_trip(tmp_path):
    cs = cscan(grid_survey(), cell_m=0.1, window_s=5e-9, eps_r=9.0)
    np.testing.assert_allclose(cs.depth_m, 0.5 * (299792458.0 / 3.0) * (cs.t_start_s + 2.5e-9))
    write_cscan(tmp_path / "c.h5", cs)
    back = read_cscan(tmp_path / "c.h5")
    np.testing.assert_array_equal(back.values, cs.values)
    assert (back.x0, back.y0, back.cell_m, back.eps_r) == (cs.x0, cs.y0, cs.cell_m, 9.0)
    np.testing.assert_array_equal(back.t_start_s, cs.t_start_s)


def test_bad_settings_are_one_line():
    s = grid_survey()
    with pytest.raises(InvalidDataError, match="cell size"):
        cscan(s, cell_m=0, window_s=4e-9)
    with pytest.raises(InvalidDataError, match="window must be between one sample"):
        cscan(s, cell_m=0.05, window_s=1.0)
    with pytest.raises(InvalidDataError, match="needs trace positions"):
        cscan(s.replace(positions_xyz=None), cell_m=0.05, window_s=4e-9)


def _steady(amplitudes, positions, n=64, t0_s=2e-9):
    """Traces whose envelope is exactly their amplitude: 8 whole periods of a cosine over the record (the FFT's
    analytic signal of a periodic tone has a flat envelope)."""
    k = np.arange(n)
    data = np.array([a * np.cos(2 * np.pi * 8 * k / n) for a in amplitudes], np.float32)
    return Survey(data=data, dt_s=1e-9, t0_s=t0_s, positions_xyz=np.c_[positions, np.zeros(len(positions))])


def test_cells_by_hand():
    """1 m cells from the lowest corner (its centre at the corner): two traces share cell (0, 0), one in (2, 0),
    one in (0, 1); the empty cells within reach get the Gaussian (sigma 1 cell for the default 2-cell reach) average
    of the others' sums over their counts; the record after a 2 ns time zero (61 ns) holds six 10 ns slices."""
    s = _steady([1.0, 3.0, 5.0, 7.0], [(0.5, -1.0), (0.7, -0.9), (2.5, -1.0), (0.5, 0.0)])
    cs = cscan(s, cell_m=1.0, window_s=10e-9)
    assert (cs.x0, cs.y0, cs.cell_m) == (0.5, -1.0, 1.0) and cs.values.shape == (6, 3, 2)
    np.testing.assert_allclose(cs.t_start_s, np.arange(6) * 10e-9)
    assert cs.depth_m is None
    total = {(0, 0): 4.0, (2, 0): 5.0, (0, 1): 7.0}
    count = {(0, 0): 2, (2, 0): 1, (0, 1): 1}

    def gauss(c):
        w = {q: np.exp(-((q[0] - c[0]) ** 2 + (q[1] - c[1]) ** 2) / 2) for q in total}
        return sum(w[q] * total[q] for q in total) / sum(w[q] * count[q] for q in total)

    want = np.array([[2.0, 7.0], [gauss((1, 0)), gauss((1, 1))], [5.0, gauss((2, 1))]])
    for k in range(6):
        np.testing.assert_allclose(cs.values[k], want, rtol=1e-5)
    # a reach under half a cell fills nothing; one cell fills the cells next to data (not diagonally)
    few = cscan(s, cell_m=1.0, window_s=10e-9, fill_m=0.4)
    assert np.isnan(few.values[0][[1, 1, 2], [0, 1, 1]]).all()
    one = cscan(s, cell_m=1.0, window_s=10e-9, fill_m=1.0)
    assert np.isfinite(one.values[0][1, 0]) and np.isfinite(one.values[0][1, 1]) and np.isfinite(one.values[0][2, 1])
    big = _steady([1.0, 2.0], [(0.0, 0.0), (3.0, 0.0)])
    b = cscan(big, cell_m=1.0, window_s=10e-9, fill_m=1.0).values[0]
    assert np.isfinite(b[1, 0]) and np.isfinite(b[2, 0])  # 1 cell from data
    b0 = cscan(_steady([1.0, 2.0], [(0.0, 0.0), (4.0, 0.0)]), cell_m=1.0, window_s=10e-9, fill_m=1.0).values[0]
    assert np.isnan(b0[2, 0])  # 2 cells from both: beyond reach
    # cells beyond the Gaussian's reach too (0 / 0 there) stay NaN, quietly
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        far = cscan(_steady([1.0, 2.0], [(0.0, 0.0), (8.0, 0.0)]), cell_m=1.0, window_s=10e-9, fill_m=1.0).values[0]
    assert np.isnan(far[2:7, 0]).all() and far[0, 0] == pytest.approx(1.0) and far[8, 0] == pytest.approx(2.0)
    # half-metre cells: the default reach is two cells (1 m), the Gaussian one cell wide: the same numbers
    half = cscan(_steady([1.0, 3.0, 5.0, 7.0], [(0.25, -0.5), (0.35, -0.45), (1.25, -0.5), (0.25, 0.0)]),
                 cell_m=0.5, window_s=10e-9)
    np.testing.assert_allclose(half.values[0], want, rtol=1e-5)


def test_slices_follow_time_zero_and_the_windows_given():
    """The slice windows are in time after time zero: with time zero at 2 ns a burst at 7-9 ns (5-7 ns after it)
    lies in the window from 4 ns, not in the one from 8 ns."""
    n = 64
    data = np.zeros((2, n), np.float32)
    data[:, 7:10] = [1.0, -2.0, 1.0]
    s = Survey(data=data, dt_s=1e-9, t0_s=2e-9, positions_xyz=np.array([[0, 0, 0.0], [1, 0, 0.0]]))
    cs = cscan(s, cell_m=1.0, window_s=4e-9, t_start_s=[4e-9, 8e-9])
    env = np.abs(hilbert(data[0].astype(float)))
    t = np.arange(n) * 1e-9 - 2e-9
    for k, a in enumerate([4e-9, 8e-9]):
        np.testing.assert_allclose(cs.values[k, 0, 0], env[(t >= a) & (t < a + 4e-9)].mean(), rtol=1e-5)
    assert cs.values[0, 0, 0] > 3 * cs.values[1, 0, 0]
    cs9 = cscan(s, cell_m=1.0, window_s=4e-9, t_start_s=4e-9, eps_r=9.0)
    np.testing.assert_allclose(cs9.depth_m, [0.5 * 299792458.0 / 3 * 6e-9])
    record = (n - 1) * 1e-9 - 2e-9  # the last sample after time zero
    cscan(s, cell_m=1.0, window_s=record, t_start_s=0.0)  # the whole record is one window
    cscan(s, cell_m=1.0, window_s=4e-9, t_start_s=record - 4e-9)  # a window ending on the last sample
    s3 = s.replace(t0_s=3e-9)  # 60 ns after time zero: six 10 ns slices exactly, the last ending on the last sample
    np.testing.assert_allclose(cscan(s3, cell_m=1.0, window_s=10e-9).t_start_s, np.arange(6) * 10e-9)
    with pytest.raises(InvalidDataError, match="^6 slices of 10001 x 10001 cells of 0.01 m: too many; use a larger "
                                               "cell or thicker slices$"):
        cscan(s3.replace(positions_xyz=np.array([[0, 0, 0.0], [100, 100, 0.0]])), cell_m=0.01, window_s=10e-9)
    cscan(s, cell_m=1.0, window_s=1e-9)  # one sample is the thinnest
    for kw, words in (({"window_s": 0.9e-9}, "^window must be between one sample \\(1 ns\\) and the record after "
                                            "time zero \\(61 ns\\), got 0.9 ns$"),
                      ({"window_s": 4e-9, "t_start_s": [-1e-9]}, "^slice windows must lie inside the record"),
                      ({"window_s": 4e-9, "t_start_s": [58e-9]}, "^slice windows must lie inside the record"),
                      ({"window_s": 4e-9, "t_start_s": []}, "^slice windows must lie inside the record"),
                      ({"window_s": 4e-9, "eps_r": 0.5}, "^eps_r must be a relative permittivity >= 1, got 0.5$")):
        with pytest.raises(InvalidDataError, match=words):
            cscan(s, cell_m=1.0, **kw)
    cscan(s, cell_m=1.0, window_s=4e-9, eps_r=1.0)  # vacuum is allowed
    with pytest.raises(InvalidDataError, match="^a C-scan needs trace positions \\(a grid survey, a track or poses\\)$"):
        cscan(s.replace(positions_xyz=None), cell_m=1.0, window_s=4e-9)
