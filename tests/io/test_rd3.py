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
    assert s.metadata["header_timewindow_s"] == pytest.approx(422.061312e-9, rel=1e-9, abs=0)
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
    assert s.dt_s == pytest.approx(0.5e-9, rel=1e-9, abs=0)
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


# ---------------------------------------------------------------- the header, the COR file and the reader by hand

from pathlib import Path  # noqa: E402

from gpr3d.core.errors import TruncatedRecordingWarning  # noqa: E402
from gpr3d.io.rd3 import is_rd3, read_cor, read_rad, read_rd3  # noqa: E402


def _pair(tmp_path, rad: str, samples, *, suffix=".rd3", name="line"):
    """A RAD header of exactly ``rad`` and a data file of ``samples`` (int16 for .rd3, int32 for .rd7)."""
    stem = tmp_path / name
    Path(str(stem) + ".rad").write_text(rad)
    data = Path(str(stem) + suffix)
    data.write_bytes(np.asarray(samples).astype("<i2" if suffix == ".rd3" else "<i4").tobytes())
    return data


def test_read_rad_keys_values_and_binary(tmp_path):
    p = tmp_path / "h.rad"
    p.write_text("samples: 40\nDate:2024-05-01\nTIME:12:30:05\nno colon here\n  Antennas : 500 MHz shielded \n")
    rad = read_rad(p)
    # keys stripped and upper-cased; the value is everything after the first colon, stripped
    assert rad == {"SAMPLES": "40", "DATE": "2024-05-01", "TIME": "12:30:05", "ANTENNAS": "500 MHz shielded"}
    p.write_bytes(b"SAMPLES:40\n\x00\x01binary")
    with pytest.raises(FormatError, match="^h.rad: RAD header holds binary bytes: not a MALA header or corrupt$"):
        read_rad(p)
    head = b"SAMPLES:40\nX:" + b"x" * (4095 - 13)
    p.write_bytes(head + b"\x00")  # a NUL at byte 4095, the last one looked at
    with pytest.raises(FormatError, match="binary bytes"):
        read_rad(p)
    p.write_bytes(head + b"x\x00")  # a NUL at byte 4096 is not looked for
    assert read_rad(p)["SAMPLES"] == "40"


def test_read_cor_fixes_hemispheres_and_bad_lines(tmp_path):
    p = tmp_path / "g.cor"
    p.write_text("1 2024-05-01 12:00:00 75.5 N 36.25 E 12.5 M 1.0\n"
                 "short line 1 2\n"
                 "x 2024-05-01 12:00:01 75.5 N 36.25 E 12.5 M 1.0\n"  # trace not a whole number
                 "5 2024-05-01 12:00:02 10.25 s 20.5 w -3.0 M 1.0\n"  # lower-case hemispheres
                 "9 2024-05-01 12:00:03 1.0 S 2.0 W 4.0\n"  # exactly eight fields
                 "7 2024-05-01 12:00:04 abc N 2.0 E 4.0 M\n")  # latitude not a number
    g = read_cor(p)
    assert g["trace"].dtype == np.float64
    np.testing.assert_array_equal(g["trace"], [1, 5, 9])
    np.testing.assert_array_equal(g["lat"], [75.5, -10.25, -1.0])
    np.testing.assert_array_equal(g["lon"], [36.25, -20.5, -2.0])
    np.testing.assert_array_equal(g["alt"], [12.5, -3.0, 4.0])


def test_is_rd3_needs_the_header_and_the_data(tmp_path):
    d = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\n", np.zeros((2, 4)))
    assert is_rd3(d) and is_rd3(d.with_suffix(".rad"))
    d7 = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\n", np.zeros((2, 4)), suffix=".rd7", name="deep")
    assert is_rd3(d7) and is_rd3(d7.with_suffix(".rad"))
    lone = tmp_path / "lone.rd3"
    lone.write_bytes(b"\0" * 16)
    assert not is_rd3(lone)  # no header
    head = tmp_path / "head.rad"
    head.write_text("SAMPLES:4\n")
    assert not is_rd3(head)  # no data
    other = tmp_path / "line.txt"
    other.write_text("x")
    assert not is_rd3(other)  # beside a pair, but not one of its names


def test_every_header_field_the_reader_uses(tmp_path):
    vals = np.arange(3 * 8).reshape(3, 8) * 7 - 80
    rad = ("SAMPLES:8\nFREQUENCY:4000\nTIMEWINDOW:3.5\nANTENNAS:1.2 GHz custom\nANTENNA SEPARATION:0.06\n"
           "DISTANCE INTERVAL:0.025\nTIME INTERVAL:0.5\nSTACKS:16\nLAST TRACE:3\n")
    s = read_rd3(_pair(tmp_path, rad, vals))[0]
    np.testing.assert_array_equal(s.data, vals.astype(np.float32))
    assert s.data.dtype == np.float32
    assert s.dt_s == pytest.approx(0.25e-9, rel=1e-9, abs=0)  # 1 / 4000 MHz, not TIMEWINDOW / SAMPLES
    assert s.frequency_hz == pytest.approx(1.2e6)  # the first number of ANTENNAS, in MHz
    assert s.offset_m == pytest.approx(0.06)
    np.testing.assert_allclose(s.positions_xyz, [[0, 0, 0], [0.025, 0, 0], [0.05, 0, 0]])
    np.testing.assert_allclose(s.timestamps_s, [0.0, 0.5, 1.0])
    m = s.metadata
    assert (m["format"], m["channel"], m["n_channels"], m["antenna"]) == ("rd3", 0, 1, "1.2 GHz custom")
    assert m["range_s"] == pytest.approx(8 * 0.25e-9, rel=1e-9, abs=0)
    assert m["header_timewindow_s"] == pytest.approx(3.5e-9, rel=1e-9, abs=0)
    assert m["sampling_frequency_hz"] == 4e9
    assert m["stacks"] == 16.0
    assert m["positions_source"] == "header DISTANCE INTERVAL, along world x"
    assert m["path"].endswith("line.rd3") and m["header_path"].endswith("line.rad") and "gps" not in m


def test_the_optional_fields_left_out(tmp_path):
    # no FREQUENCY: the interval is TIMEWINDOW / SAMPLES; no ANTENNAS, separation, intervals, stacks, last trace
    s = read_rd3(_pair(tmp_path, "SAMPLES:8\nTIMEWINDOW:4\n", np.ones((2, 8))))[0]
    assert s.dt_s == pytest.approx(0.5e-9, rel=1e-9, abs=0)
    assert s.frequency_hz is None and s.offset_m == 0.0
    assert s.positions_xyz is None and s.timestamps_s is None
    assert s.metadata["sampling_frequency_hz"] is None and s.metadata["stacks"] is None
    assert s.metadata["positions_source"] is None and s.metadata["antenna"] == ""
    # an antenna named without a number gives no frequency
    s = read_rd3(_pair(tmp_path, "SAMPLES:8\nFREQUENCY:1000\nANTENNAS:shielded\n", np.ones((2, 8)), name="b"))[0]
    assert s.frequency_hz is None and s.metadata["header_timewindow_s"] is None


def test_rd7_is_32_bit(tmp_path):
    vals = np.array([[2**20, -(2**20), 5, -7], [1, 2, 3, 2**30]])
    s = read_rd3(_pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\n", vals, suffix=".rd7"))[0]
    np.testing.assert_array_equal(s.data, vals.astype(np.float32))


@pytest.mark.parametrize("rad, needles", [
    ("FREQUENCY:1000\n", ["lacks 'SAMPLES'"]),
    ("SAMPLES:1\nFREQUENCY:1000\n", ["SAMPLES = 1", "implausible"]),
    ("SAMPLES:1000001\nFREQUENCY:1000\n", ["SAMPLES = 1000001"]),
    ("SAMPLES:eight\nFREQUENCY:1000\n", ["RAD field 'SAMPLES' = 'eight' is not a number"]),
    ("SAMPLES:8\n", ["lacks 'TIMEWINDOW'"]),  # neither FREQUENCY nor TIMEWINDOW
    ("SAMPLES:8\nFREQUENCY:0\n", ["header field FREQUENCY = 0.0 is not a positive number"]),
    ("SAMPLES:8\nTIMEWINDOW:-4\n", ["header field TIMEWINDOW = -4.0 is not"]),
    ("SAMPLES:8\nFREQUENCY:fast\n", ["'FREQUENCY' = 'fast'"]),
    ("SAMPLES:8\nTIMEWINDOW:long\n", ["'TIMEWINDOW' = 'long'"]),
    ("SAMPLES:8\nFREQUENCY:1000\nLAST TRACE:end\n", ["'LAST TRACE' = 'end'"]),
    ("SAMPLES:8\nFREQUENCY:1000\nDISTANCE INTERVAL:?\n", ["'DISTANCE INTERVAL' = '?'"]),
    ("SAMPLES:8\nFREQUENCY:1000\nTIME INTERVAL:?\n", ["'TIME INTERVAL' = '?'"]),
    ("SAMPLES:8\nFREQUENCY:1000\nANTENNA SEPARATION:wide\n", ["'ANTENNA SEPARATION' = 'wide'"]),
    ("SAMPLES:8\nFREQUENCY:0.5\n", ["sample interval from FREQUENCY is 2e-06 s, which no radar records"]),  # 2 us
    # counts that are no counts, intervals no radar records (issue 31: once int(nan) tracebacks, or accepted)
    ("SAMPLES:nan\nFREQUENCY:1000\n", ["header field SAMPLES = nan is not a whole number"]),
    ("SAMPLES:inf\nFREQUENCY:1000\n", ["header field SAMPLES = inf is not a whole number"]),
    ("SAMPLES:8\nFREQUENCY:1000\nLAST TRACE:inf\n", ["header field LAST TRACE = inf is not a whole number"]),
    ("SAMPLES:8\nFREQUENCY:1000\nLAST TRACE:0\n", ["header field LAST TRACE = 0 is implausible"]),
    ("SAMPLES:8\nTIMEWINDOW:1e-30\n", ["sample interval from TIMEWINDOW / SAMPLES is 1.25e-40 s"]),
    ("SAMPLES:8\nFREQUENCY:1e20\n", ["sample interval from FREQUENCY is 1e-26 s"]),
    ("SAMPLES:8\nFREQUENCY:1000\nSTACKS:many\n", ["STACKS", "'many'"]),
])
def test_header_errors_name_the_field(tmp_path, rad, needles):
    with pytest.raises(FormatError) as e:
        read_rd3(_pair(tmp_path, rad, np.ones((4, 8))))
    assert str(e.value).startswith("line.rad: ")  # the file first, then the field
    for n in needles:
        assert n in str(e.value)


def test_a_missing_half_of_the_pair_is_named(tmp_path):
    d = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\n", np.ones((2, 4)))
    d.with_suffix(".rad").unlink()
    with pytest.raises(FormatError, match=r"^line.rd3: no \.rad header beside the data \(MALA needs both\)$"):
        read_rd3(d)
    h = tmp_path / "head.rad"
    h.write_text("SAMPLES:4\n")
    with pytest.raises(FormatError, match=r"^head.rad: no \.rd3/\.rd7 data file beside the header$"):
        read_rd3(h)


def test_the_boundaries_of_the_plausible(tmp_path):
    s = read_rd3(_pair(tmp_path, "SAMPLES:2\nFREQUENCY:1\n", np.ones((3, 2))))[0]  # 2 samples, 1 us: allowed
    assert s.shape == (3, 2) and s.dt_s == pytest.approx(1e-6)
    s = read_rd3(_pair(tmp_path, "SAMPLES:1000000\nFREQUENCY:1000\n", np.ones((1, 10**6)), name="long"))[0]
    assert s.shape == (1, 10**6)


def test_samples_that_disagree_with_the_data_are_refused_not_sheared(tmp_path):
    # 4 traces of 8 samples written, the header says 6 samples: once a warning and every trace misaligned
    d = _pair(tmp_path, "SAMPLES:6\nFREQUENCY:1000\nLAST TRACE:4\n", np.ones((4, 8)))
    with pytest.raises(FormatError, match=r"^line.rad: SAMPLES = 6 does not fit line.rd3 \(64 bytes: no whole number "
                                          r"of 6-sample traces, but 4 traces \(LAST TRACE\) of 8 samples\): the header "
                                          r"or the data is wrong$"):
        read_rd3(d)
    # a file cut at a trace's end fits SAMPLES still: a shorter recording, read with a warning
    d = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\nLAST TRACE:4\n", np.ones((2, 4)), name="cut")
    with pytest.warns(TruncatedRecordingWarning, match="LAST TRACE says 4 traces, file holds 2"):
        assert read_rd3(d)[0].shape == (2, 4)


def test_last_trace_more_than_the_file_warns_and_reads_what_is_there(tmp_path):
    d = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\nLAST TRACE:5\n", np.ones((3, 4)))
    with pytest.warns(TruncatedRecordingWarning, match="LAST TRACE says 5 traces, file holds 3"):
        s = read_rd3(d)[0]
    assert s.n_traces == 3
    with pytest.raises(FormatError, match="^c.rd3: file holds 3 traces but LAST TRACE says 2"):
        read_rd3(_pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\nLAST TRACE:2\n", np.ones((3, 4)), name="c"))


def test_a_partial_last_trace_is_dropped(tmp_path):
    d = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\n", np.arange(10))  # 2 traces and half of one
    with pytest.warns(TruncatedRecordingWarning, match="ends mid-trace; dropped 1 partial trace"):
        s = read_rd3(d)[0]
    np.testing.assert_array_equal(s.data, np.arange(8).reshape(2, 4))


def test_cor_gps_places_the_traces(tmp_path):
    """Fixes at traces 1 and 3 (COR counts from 1), 0.001 deg of latitude apart: trace 0 at the first fix, trace 2
    at the second (111 m north), trace 1 half-way; the GPS wins over DISTANCE INTERVAL."""
    d = _pair(tmp_path, "SAMPLES:4\nFREQUENCY:1000\nDISTANCE INTERVAL:0.05\n", np.ones((3, 4)))
    d.with_suffix(".cor").write_text("1 2024-05-01 12:00:00 60.000 N 10.0 E 100.0 M 1.0\n"
                                     "3 2024-05-01 12:00:02 60.001 N 10.0 E 102.0 M 1.0\n")
    s = read_rd3(d)[0]
    assert s.metadata["positions_source"] == "COR GPS (local ENU metres about origin)"
    assert s.metadata["gps"] == {"file": "line.cor", "fixes": 2, "origin_lat_lon_alt": pytest.approx([60.0, 10.0,
                                                                                                      100.0])}
    north = s.positions_xyz[:, 1]
    assert north[0] == pytest.approx(0.0, abs=1e-6) and north[2] == pytest.approx(111.4, abs=0.5)
    assert north[1] == pytest.approx(north[2] / 2, rel=1e-6)
    np.testing.assert_allclose(s.positions_xyz[:, 2], [0.0, 1.0, 2.0], atol=1e-3)  # the altitude, up
    # one fix: no positions from it, the header's interval stays
    d.with_suffix(".cor").write_text("1 2024-05-01 12:00:00 60.000 N 10.0 E 100.0 M 1.0\n")
    s = read_rd3(d)[0]
    assert s.metadata["positions_source"].startswith("header") and s.metadata["gps"] == {"file": "line.cor",
                                                                                           "fixes": 1}
