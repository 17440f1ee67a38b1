import numpy as np
import pytest

import gpr3d
from gpr3d.core.errors import FormatError
from tests.conftest import real_file
from tests.io.makers import expected_values, write_rd3


def test_mala_facts_and_gps():
    s = gpr3d.read(real_file("impdar_mala_500MHz/ten_col.rd3"))
    assert s.shape == (10, 512)
    assert s.frequency_hz == 500e6
    assert s.offset_m == pytest.approx(0.18)
    assert s.metadata["header_timewindow_s"] == pytest.approx(422.061312e-9)
    assert s.metadata["gps"]["fixes"] == 3
    assert s.metadata["gps"]["origin_lat_lon_alt"][0] == pytest.approx(75.63203)
    nogps = gpr3d.read(real_file("impdar_mala_500MHz/ten_col_nogps.rd3"))
    assert nogps.positions_xyz is None and "gps" not in nogps.metadata
    np.testing.assert_array_equal(nogps.data, s.data)


def test_mala_sample_interval_from_the_spectrum():
    """The spectrum must peak near the antenna's 500 MHz with the chosen sample interval."""
    s = gpr3d.read(real_file("impdar_mala_500MHz/ten_col.rd3"))
    x = s.data - s.data.mean(axis=1, keepdims=True)
    spec = np.abs(np.fft.rfft(x, axis=1)).mean(axis=0)
    f = np.fft.rfftfreq(s.n_samples, s.dt_s)
    peak = f[1 + np.argmax(spec[1:])]
    assert 350e6 < peak < 650e6


def test_mala_raw_samples():
    p = real_file("impdar_mala_500MHz/ten_col.rd3")
    raw = np.frombuffer(p.read_bytes(), dtype="<i2").reshape(10, 512)
    np.testing.assert_array_equal(gpr3d.read(p).data, raw)


def test_synthetic_rd3(tmp_path):
    p = write_rd3(tmp_path / "line", n_traces=5, n_samples=40, fs_mhz=2000.0)
    s = gpr3d.read(p.with_suffix(".rad"))
    np.testing.assert_array_equal(s.data, expected_values(5, 40)[0])
    assert s.dt_s == pytest.approx(0.5e-9)
    assert s.positions_xyz[-1, 0] == pytest.approx(0.2)
    assert s.frequency_hz == 800e6


def test_last_trace_disagrees(tmp_path):
    p = write_rd3(tmp_path / "x", n_traces=5, last=3)
    with pytest.raises(FormatError, match="LAST TRACE says 3"):
        gpr3d.read(p)


def test_rad_not_numeric(tmp_path):
    p = write_rd3(tmp_path / "y")
    rad = p.with_suffix(".rad")
    rad.write_text(rad.read_text().replace("SAMPLES:40", "SAMPLES:forty"))
    with pytest.raises(FormatError, match="SAMPLES"):
        gpr3d.read(p)
