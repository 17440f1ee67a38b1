"""The helpers the readers share, by hand: files, sidecars, trace counts, header numbers, GPS to metres."""

import math
import warnings

import numpy as np
import pytest

from gpr3d.core.errors import FormatError, GPR3DError, TruncatedRecordingWarning
from gpr3d.io._common import (
    check_file, check_finite, data_and_header, finite_positive, gps_positions, hdf5_errors, local_metres,
    nmea_degrees, sidecar, warn_fewer_traces, whole_traces,
)


def test_check_file(tmp_path):
    with pytest.raises(FormatError, match="^nope.bin: no such file$"):
        check_file(tmp_path / "nope.bin")
    with pytest.raises(FormatError, match=r"is a folder, not a file$"):
        check_file(tmp_path)
    (tmp_path / "e.bin").write_bytes(b"")
    with pytest.raises(FormatError, match="^e.bin: file is empty$"):
        check_file(tmp_path / "e.bin")
    (tmp_path / "one.bin").write_bytes(b"x")
    assert check_file(str(tmp_path / "one.bin")) == tmp_path / "one.bin"


def test_sidecars_in_any_letter_case(tmp_path):
    (tmp_path / "line.DT1").write_bytes(b"x")
    (tmp_path / "line.hd").write_bytes(b"x")
    (tmp_path / "Line.Gps").write_bytes(b"x")
    base = tmp_path / "line.DT1"
    assert sidecar(base, ".hd") == tmp_path / "line.hd"
    assert sidecar(base, ".HD") == tmp_path / "line.hd"  # the lower case tried too
    assert sidecar(base, ".gps") == tmp_path / "Line.Gps"  # the stem in another letter case: found by the scan
    assert sidecar(base, ".cor") is None
    assert sidecar(base, ".xyz", ".hd") == tmp_path / "line.hd"  # the first that exists
    assert sidecar(tmp_path / "missing_dir" / "a.DT1", ".hd") is None


def test_whole_traces(tmp_path):
    assert whole_traces("f.bin", 300, 100) == 3
    with pytest.warns(TruncatedRecordingWarning, match=r"^f.bin: recording ends mid-scan; dropped 1 partial scan "
                                                       r"\(20 bytes\), kept 3$"):
        assert whole_traces(tmp_path / "f.bin", 320, 100, "scan") == 3
    with pytest.raises(FormatError, match=r"^f.bin: holds no complete trace \(99 data bytes, one trace needs 100\)$"):
        whole_traces("f.bin", 99, 100)
    with pytest.raises(FormatError, match="^f.bin: trace size 0 bytes is impossible$"):
        whole_traces("f.bin", 99, 0)
    with pytest.raises(FormatError, match="trace size -4 bytes"):
        whole_traces("f.bin", 99, -4)


def test_finite_positive():
    assert finite_positive("h", "range", "2.5") == 2.5
    assert finite_positive("h", "range", 0, allow_zero=True) == 0.0
    for bad, words in ((0, "range = 0.0 is not a positive number"), (-1, "range = -1.0 is not"),
                       (float("inf"), "range = inf is not"), (float("nan"), "range = nan is not"),
                       ("abc", "range = 'abc' is not a number"), (None, "range = None is not a number")):
        with pytest.raises(FormatError, match=f"^h: header field {words}"):
            finite_positive("h", "range", bad)
    with pytest.raises(FormatError, match="-1.0 is not a positive number"):
        finite_positive("h", "range", -1, allow_zero=True)


def test_check_finite():
    check_finite("d", np.ones((2, 2)))
    with pytest.raises(FormatError, match="^d: 2 samples are NaN or infinite$"):
        check_finite("d", np.array([1.0, np.nan, -np.inf]))


def test_nmea_degrees_by_hand():
    assert nmea_degrees("4739.5000", "N") == pytest.approx(47 + 39.5 / 60)
    assert nmea_degrees("12218.0000", " w ") == pytest.approx(-(122 + 18 / 60))
    assert nmea_degrees("00030.0000", "E") == pytest.approx(0.5)
    assert nmea_degrees("0000.6000", "s") == pytest.approx(-0.01)
    assert nmea_degrees("100.0", "N") == 1.0  # exactly one degree, no minutes


def test_local_metres_by_hand():
    """At 60 deg N: a degree of longitude is N cos(60) pi/180 and a degree of latitude M pi/180 (WGS-84 radii of
    curvature), and the altitude is the third axis."""
    a, e2 = 6378137.0, 6.69437999014e-3
    s2 = math.sin(math.radians(60)) ** 2
    n_r, m_r = a / math.sqrt(1 - e2 * s2), a * (1 - e2) / (1 - e2 * s2) ** 1.5
    enu, origin = local_metres([60.0, 60.001, 60.0], [10.0, 10.0, 10.002], [5.0, 7.0, 4.0])
    assert origin == (60.0, 10.0, 5.0)
    np.testing.assert_allclose(enu[1], [0.0, 0.001 * math.pi / 180 * m_r, 2.0], atol=1e-9)
    np.testing.assert_allclose(enu[2], [0.002 * math.pi / 180 * n_r * 0.5, 0.0, -1.0], atol=1e-9)
    assert 0.001 * math.pi / 180 * m_r == pytest.approx(111.41, abs=0.02)  # the known length of a milli-degree
    enu2, o2 = local_metres([60.0], [10.0], [0.0], origin=(59.999, 10.0, 1.0))
    assert o2 == (59.999, 10.0, 1.0) and enu2[0, 2] == -1.0 and enu2[0, 1] > 111.0


def test_gps_positions_need_two_advancing_fixes():
    pos, origin = gps_positions([0, 10], [60.0, 60.001], [10.0, 10.0], [0.0, 1.0], np.arange(11))
    assert origin == (60.0, 10.0, 0.0)
    np.testing.assert_allclose(pos[5], [0.0, pos[10, 1] / 2, 0.5], atol=1e-9)
    np.testing.assert_allclose(pos[:, 0], 0.0, atol=1e-9)
    assert gps_positions([0], [60.0], [10.0], [0.0], np.arange(3)) == (None, None)
    assert gps_positions([0, 0], [60.0, 61.0], [10.0, 10.0], [0.0, 0.0], np.arange(3)) == (None, None)
    assert gps_positions([5, 2], [60.0, 61.0], [10.0, 10.0], [0.0, 0.0], np.arange(3)) == (None, None)


def test_data_and_header_pairs(tmp_path):
    (tmp_path / "a.DT1").write_bytes(b"x")
    (tmp_path / "a.HD").write_bytes(b"x")
    assert data_and_header(tmp_path / "a.HD", (".dt1",), ".hd", "pulseEKKO") == (tmp_path / "a.DT1",
                                                                                  tmp_path / "a.HD")
    assert data_and_header(tmp_path / "a.DT1", (".dt1",), ".hd", "pulseEKKO") == (tmp_path / "a.DT1",
                                                                                   tmp_path / "a.HD")
    (tmp_path / "b.HD").write_bytes(b"x")
    with pytest.raises(FormatError, match=r"^b.HD: no \.dt1 data file beside the header$"):
        data_and_header(tmp_path / "b.HD", (".dt1",), ".hd", "pulseEKKO")
    (tmp_path / "c.DT1").write_bytes(b"x")
    with pytest.raises(FormatError, match=r"^c.DT1: no \.hd header beside the data \(pulseEKKO needs both\)$"):
        data_and_header(tmp_path / "c.DT1", (".dt1",), ".hd", "pulseEKKO")
    (tmp_path / "d.DT1").write_bytes(b"")
    (tmp_path / "d.HD").write_bytes(b"x")
    with pytest.raises(FormatError, match="^d.DT1: file is empty$"):  # both checked as files
        data_and_header(tmp_path / "d.HD", (".dt1",), ".hd", "pulseEKKO")


def test_warn_fewer_traces():
    with pytest.warns(TruncatedRecordingWarning, match=r"^x.DT1: NUMBER OF TRACES says 9 traces, file holds 4; "
                                                       r"reading 4$"):
        warn_fewer_traces("/some/where/x.DT1", 9, 4, "NUMBER OF TRACES")


@pytest.mark.parametrize("exc, kind", [(OSError("bad superblock\nmore"), "bad superblock"), (RuntimeError(""),
                                       "RuntimeError"), (KeyError("x"), "'x'"), (ValueError("v"), "v"),
                                       (TypeError("t"), "t"), (IndexError("i"), "i")])
def test_hdf5_errors_become_one_line(exc, kind):
    with pytest.raises(FormatError) as e:
        with hdf5_errors("/d/f.h5"):
            raise exc
    assert str(e.value) == f"f.h5: HDF5 content is corrupt or truncated ({kind})"


def test_hdf5_errors_let_ours_and_others_through():
    with pytest.raises(GPR3DError, match="ours"):
        with hdf5_errors("f.h5"):
            raise GPR3DError("ours")
    with pytest.raises(ZeroDivisionError):
        with hdf5_errors("f.h5"):
            raise ZeroDivisionError
    with hdf5_errors("f.h5"):
        pass
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(FormatError, match=r"\(" + "x" * 160 + r"\)$"):  # the detail cut to 160 characters
            with hdf5_errors("f.h5"):
                raise OSError("x" * 400)
