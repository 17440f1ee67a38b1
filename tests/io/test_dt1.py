import struct

import numpy as np
import pytest

import gpr3d
from gpr3d.core.errors import FormatError, TruncatedRecordingWarning
from gpr3d.io.dt1 import read_dt1, read_hd
from gpr3d.io.trajectory import attach_track, read_xyz_track
from tests.conftest import REAL, real_file
from tests.io.makers import expected_values, write_dt1


def test_pulseekko_50mhz_facts():
    s = gpr3d.read(real_file("gprpy_sns_50MHz/XLINE00.DT1"))
    assert s.shape == (531, 1500)  # README: 531 traces x 1500 points
    assert s.time_window_s == pytest.approx(1200e-9)
    assert s.frequency_hz == 50e6
    assert s.offset_m == pytest.approx(3 * 0.3048)  # 3 ft
    # 2 ft steps, stored in feet and converted to metres
    assert np.diff(s.positions_xyz[:, 0]) == pytest.approx(np.full(530, 0.6096))


def test_pulseekko_samples_match_raw_layout():
    """Trace i, sample k sits at byte i*(128 + 2n) + 128 + 2k (format description)."""
    p = real_file("gprpy_sns_50MHz/XLINE00.DT1")
    raw = p.read_bytes()
    s = gpr3d.read(p)
    n = s.n_samples
    for i in (0, 17, 530):
        for k in (0, 100, 1499):
            (v,) = struct.unpack_from("<h", raw, i * (128 + 2 * n) + 128 + 2 * k)
            assert s.data[i, k] == v


def test_grid_lines_all_read():
    real_file("gpro_sns_100MHz_grid/XLINE00.DT1")
    lines = sorted((REAL / "gpro_sns_100MHz_grid").glob("XLINE*.DT1"))
    assert len(lines) == 25
    for p in lines:
        s = gpr3d.read(p)
        hd = read_hd(p.with_suffix(".HD"))
        assert s.n_traces == int(hd["NUMBER OF TRACES"])
        assert s.n_samples == 250 and s.time_window_s == pytest.approx(200e-9)
        assert s.frequency_hz == 100e6
        assert np.allclose(np.diff(s.positions_xyz[:, 0]), 0.05, atol=1e-4)


def test_gps_xyz_track_places_the_line():
    s = gpr3d.read(real_file("gprpy_sns_50MHz/XLINE00.DT1"))
    track = read_xyz_track(REAL / "gprpy_sns_50MHz/GPS.xyz")
    placed = attach_track(s, track)
    # every trace lies on the track's bounding box, and steps keep their length (on a near-straight track)
    lo, hi = track.min(axis=0), track.max(axis=0)
    assert np.all(placed.positions_xyz >= lo - 1e-6) and np.all(placed.positions_xyz <= hi + 1e-6)
    steps = np.linalg.norm(np.diff(placed.positions_xyz[:, :2], axis=0), axis=1)
    assert np.median(steps) == pytest.approx(0.6096, rel=0.02)
    assert placed.headings_rad is not None


def test_synthetic_dt1_exact(tmp_path):
    p = write_dt1(tmp_path / "LINE", n_traces=6, n_points=50, units="ft", step=0.5)
    s = read_dt1(p.with_suffix(".HD"))  # either file of the pair
    np.testing.assert_array_equal(s[0].data, expected_values(6, 50)[0])
    assert s[0].dt_s == pytest.approx(100e-9 / 50)
    assert s[0].positions_xyz[-1, 0] == pytest.approx(5 * 0.5 * 0.3048)
    assert s[0].timestamps_s[1] - s[0].timestamps_s[0] == pytest.approx(0.5)


def test_32_bit_samples_read_exactly(tmp_path):
    """Trace headers saying 4 bytes per point: 32-bit samples, values beyond the 16-bit range kept exactly."""
    p = write_dt1(tmp_path / "WIDE", n_traces=5, n_points=40, bits=32)
    s = gpr3d.read(p)
    want = expected_values(5, 40, 1, 32)[0]
    assert np.abs(want).max() > 2**15  # no 16-bit reading could give these
    np.testing.assert_array_equal(s.data, want.astype(np.float32))


def test_header_claims_more_traces_warns(tmp_path):
    p = write_dt1(tmp_path / "CUT", n_traces=4, hd_traces=9)
    with pytest.warns(TruncatedRecordingWarning, match="HD header says 9 traces, file holds 4"):
        assert gpr3d.read(p).n_traces == 4


def test_header_claims_fewer_traces_is_an_error(tmp_path):
    p = write_dt1(tmp_path / "MORE", n_traces=4, hd_traces=2)
    with pytest.raises(FormatError, match="file holds 4 traces but the HD header says 2"):
        gpr3d.read(p)


def test_trace_header_points_mismatch(tmp_path):
    p = write_dt1(tmp_path / "BAD", n_traces=4, bad_trace=2)
    with pytest.raises(FormatError, match="trace 2 header says 51 points, HD says 50"):
        gpr3d.read(p)


def test_missing_header_file(tmp_path):
    p = write_dt1(tmp_path / "NOHD")
    p.with_suffix(".HD").unlink()
    with pytest.raises(FormatError, match="no .hd header beside the data"):
        read_dt1(p)


def test_truncated_mid_trace(tmp_path):
    p = write_dt1(tmp_path / "HALF", n_traces=5)
    p.write_bytes(p.read_bytes()[:-7])
    with pytest.warns(TruncatedRecordingWarning, match="dropped 1 partial trace"):
        s = gpr3d.read(p)
    assert s.n_traces == 4


def test_pulseekko_gps_sidecar(tmp_path):
    p = write_dt1(tmp_path / "GLINE", n_traces=5)
    # fixes at traces 1 and 5, 0.01' of longitude apart at the equator (18.55 m east)
    p.with_suffix(".GPS").write_text(
        "Trace #1 at position 0.000000\n$GPGGA,120000,0000.0000,N,01000.0000,E,1,08,1.0,5.0,M,,M,,*00\n"
        "Trace #5 at position 1.000000\n$GPGGA,120004,0000.0000,N,01000.0100,E,1,08,1.0,5.0,M,,M,,*00\n"
    )
    s = gpr3d.read(p)
    assert s.metadata["gps"]["fixes"] == 2
    assert s.positions_xyz[-1, 0] == pytest.approx(0.01 / 60 * np.pi / 180 * 6378137.0, rel=1e-6)
    np.testing.assert_allclose(np.diff(s.positions_xyz[:, 0]), s.positions_xyz[-1, 0] / 4)
