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
