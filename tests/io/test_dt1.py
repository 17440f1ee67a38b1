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
    assert s.time_window_s == pytest.approx(1200e-9, rel=1e-9, abs=0)
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
        assert s.n_samples == 250 and s.time_window_s == pytest.approx(200e-9, rel=1e-9, abs=0)
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
    assert s[0].dt_s == pytest.approx(100e-9 / 50, rel=1e-9, abs=0)
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


def test_hd_header_by_hand(tmp_path):
    """Keys upper-cased, values after the first '=', the date and system lines; binary bytes refused."""
    hd = tmp_path / "H.HD"
    hd.write_text("1234\nData Collected with pulseEKKO PRO\n2021-03-04\nnumber of traces = 12\n"
                  "TOTAL TIME WINDOW  =  100.5 ns\nNOTE = a=b\n")
    out = read_hd(hd)
    assert out["NUMBER OF TRACES"] == "12" and out["TOTAL TIME WINDOW"] == "100.5 ns" and out["NOTE"] == "a=b"
    assert out["_date"] == "2021-03-04" and out["_system"] == "Data Collected with pulseEKKO PRO"
    hd.write_bytes(b"1234\nNUMBER OF TRACES = 1\x00\n")
    with pytest.raises(FormatError, match=r"H.HD: HD header holds binary bytes: not a pulseEKKO header or corrupt$"):
        read_hd(hd)
    hd.write_bytes(b"1234\n" + b" " * 5000 + b"\x00")  # a zero beyond the first 4096 bytes is not looked for
    assert read_hd(hd) == {}


def test_hd_fields_the_reader_needs_and_uses(tmp_path):
    """Frequency, antenna separation (in the position unit), time-zero point, stacks, step, and the lines the
    reader refuses, each by its message."""
    p = write_dt1(tmp_path / "F", n_traces=6, n_points=50, units="cm", step=2.0, freq=250.0, sep=40.0)
    s = gpr3d.read(p)
    assert s.frequency_hz == 250e6 and s.offset_m == pytest.approx(0.40)
    m = s.metadata
    assert (m["format"], m["channel"], m["n_channels"], m["bytes_per_point"]) == ("dt1", 0, 1, 2)
    assert m["antenna"] == "250 MHz pulseEKKO" and m["range_s"] == pytest.approx(100e-9, rel=1e-9, abs=0)
    assert m["step_m"] == pytest.approx(0.02) and m["stacks"] == 4 and m["header_timezero_point"] == 3.5
    assert m["system"] == "Data Collected with test maker" and m["date"] == "2020-01-02"
    assert m["path"].endswith("F.DT1") and m["header_path"].endswith("F.HD") and m["position_units"] == "cm"
    assert m["positions_source"] == "trace header positions (cm), along world x"
    assert m["timestamps_source"] == "trace header time of day (s)"
    hd = p.with_suffix(".HD")
    text = hd.read_text()
    for old, new, words in (("NUMBER OF PTS/TRC  = 50", "NUMBER OF PTS/TRC  = 1", "NUMBER OF PTS/TRC = 1 is implausible"),
                            ("NUMBER OF TRACES   = 6", "NUMBER OF TRACES   = 0", "NUMBER OF TRACES = 0 is implausible \\(expected 1..100000000\\)"),
                            ("NUMBER OF TRACES   = 6\n", "", "HD header lacks 'NUMBER OF TRACES'"),
                            ("TOTAL TIME WINDOW  = 100.0", "TOTAL TIME WINDOW  = lots",
                             "HD field 'TOTAL TIME WINDOW' = 'lots' is not a number"),
                            ("POSITION UNITS     = cm", "POSITION UNITS     = furlongs", "unknown POSITION UNITS 'furlongs'")):
        hd.write_text(text.replace(old, new))
        with pytest.raises(FormatError, match=words):
            gpr3d.read(p)
    # no frequency, separation or step given: none, 0, none
    hd.write_text("\n".join(ln for ln in text.splitlines() if not ln.startswith(("NOMINAL", "ANTENNA", "STEP"))))
    s = gpr3d.read(p)
    assert s.frequency_hz is None and s.offset_m == 0.0 and s.metadata["antenna"] == "" and s.metadata["step_m"] is None


def test_two_points_per_trace_and_one_trace_are_enough(tmp_path):
    s = gpr3d.read(write_dt1(tmp_path / "TINY", n_traces=1, n_points=2))
    assert s.shape == (1, 2) and s.positions_xyz is None  # one trace has no extent along the line
    np.testing.assert_array_equal(s.data, expected_values(1, 2)[0])


def test_positions_and_times_only_when_they_make_sense(tmp_path):
    """Trace positions all equal: none; times of day that go backwards, or all zero: none."""
    import struct

    p = write_dt1(tmp_path / "T", n_traces=4, n_points=10)
    raw = bytearray(p.read_bytes())
    rec = 128 + 10 * 2
    for i in range(4):
        raw[i * rec + 4:i * rec + 8] = struct.pack("<f", 1.5)  # the same position in every trace
    raw[2 * rec + 92:2 * rec + 96] = struct.pack("<f", 999.0)  # trace 2 later than trace 3
    p.write_bytes(bytes(raw))
    s = gpr3d.read(p)
    assert s.positions_xyz is None and s.timestamps_s is None and s.metadata["timestamps_source"] is None
    for i in range(4):
        raw[i * rec + 92:i * rec + 96] = struct.pack("<f", 0.0)
    p.write_bytes(bytes(raw))
    assert gpr3d.read(p).timestamps_s is None


def test_the_gps_file_by_hand(tmp_path):
    """Trace lines and GGA sentences; fixes of quality 0, other sentences and broken lines are skipped; a missing
    altitude is 0; southern and western hemispheres are negative."""
    from gpr3d.io.dt1 import read_sns_gps

    g = tmp_path / "x.GPS"
    g.write_text("Trace #3 at position 0.0\n$GPGGA,120000,4530.0000,S,01015.0000,W,1,08,1.0,,M,,M,,*00\n"
                 "Trace #4 at position 0.1\n$GPGGA,120001,4530.0000,N,01015.0000,E,0,08,1.0,5.0,M,,M,,*00\n"
                 "Trace #5 at position 0.2\n$GPRMC,120002,A,4530.0000,N,01015.0000,E*00\n"
                 "$GPGGA,120002,4530.0000,N,01015.0000,E,1,08,1.0,7.0,M,,M,,*00\n"
                 "Trace #6 at position 0.3\n$GPGGA,120003,4530.0000,N\n"
                 "Trace #7 at position 0.4\n$GPGGA,120004,4531.5000,N,01016.5000,E,2,08,1.0,9.5,M,,M,,*00\n")
    out = read_sns_gps(g)
    # trace 5: the GGA after another sentence counts; trace 6's GGA is cut short
    np.testing.assert_array_equal(out["trace"], [3.0, 5.0, 7.0])
    np.testing.assert_allclose(out["lat"], [-45.5, 45.5, 45.525])
    np.testing.assert_allclose(out["lon"], [-10.25, 10.25, 10.275])
    np.testing.assert_allclose(out["alt"], [0.0, 7.0, 9.5])


def test_is_dt1_needs_both_files(tmp_path):
    from gpr3d.io.dt1 import is_dt1

    p = write_dt1(tmp_path / "PAIR")
    assert is_dt1(p) and is_dt1(p.with_suffix(".HD"))
    assert not is_dt1(tmp_path / "PAIR.txt")
    p.with_suffix(".HD").unlink()
    assert not is_dt1(p)


# ---------------------------------------------------------------- every message names its file; the edges

import struct  # noqa: E402

from gpr3d.core.errors import TruncatedRecordingWarning  # noqa: E402
from gpr3d.io.dt1 import read_dt1, read_sns_gps  # noqa: E402


@pytest.mark.parametrize("old, new, message", [
    ("NUMBER OF TRACES   = 6\n", "", "E.HD: HD header lacks 'NUMBER OF TRACES'"),
    ("NUMBER OF TRACES   = 6", "NUMBER OF TRACES   = six", "E.HD: HD field 'NUMBER OF TRACES' = 'six' is not a number"),
    ("NUMBER OF PTS/TRC  = 50", "NUMBER OF PTS/TRC  = x", "E.HD: HD field 'NUMBER OF PTS/TRC' = 'x' is not a number"),
    ("NUMBER OF PTS/TRC  = 50", "NUMBER OF PTS/TRC  = 1000001", "E.HD: header field NUMBER OF PTS/TRC = 1000001 is implausible (expected 2..1000000)"),
    ("NUMBER OF TRACES   = 6", "NUMBER OF TRACES   = -1", "E.HD: header field NUMBER OF TRACES = -1 is implausible (expected 1..100000000)"),
    ("TOTAL TIME WINDOW  = 100.0", "TOTAL TIME WINDOW  = -5",
     "E.HD: header field TOTAL TIME WINDOW = -5.0 is not a positive number"),
    ("TOTAL TIME WINDOW  = 100.0\n", "", "E.HD: HD header lacks 'TOTAL TIME WINDOW'"),
    # counts that are no counts, and a time window no radar records (issue 31: once a traceback, or accepted)
    ("NUMBER OF PTS/TRC  = 50", "NUMBER OF PTS/TRC  = nan", "E.HD: header field NUMBER OF PTS/TRC = nan is not a whole"),
    ("NUMBER OF PTS/TRC  = 50", "NUMBER OF PTS/TRC  = 50.5", "E.HD: header field NUMBER OF PTS/TRC = 50.5 is not a whole"),
    ("NUMBER OF TRACES   = 6", "NUMBER OF TRACES   = inf", "E.HD: header field NUMBER OF TRACES = inf is not a whole"),
    ("NUMBER OF TRACES   = 6", "NUMBER OF TRACES   = 1e300", "E.HD: header field NUMBER OF TRACES = 1e+300 is implaus"),
    ("TOTAL TIME WINDOW  = 100.0", "TOTAL TIME WINDOW  = 1e-30",
     "E.HD: the sample interval from TOTAL TIME WINDOW / NUMBER OF PTS/TRC is 2e-41 s, which no radar records"),
    ("TOTAL TIME WINDOW  = 100.0", "TOTAL TIME WINDOW  = 1e9",
     "E.HD: the sample interval from TOTAL TIME WINDOW / NUMBER OF PTS/TRC is 0.02 s, which no radar records"),
    ("NOMINAL FREQUENCY  = 250.0", "NOMINAL FREQUENCY  = high", "E.HD: HD field 'NOMINAL FREQUENCY' = 'high'"),
    ("ANTENNA SEPARATION = 0.4", "ANTENNA SEPARATION = wide", "E.HD: HD field 'ANTENNA SEPARATION' = 'wide'"),
    ("TIMEZERO AT POINT  = 3.5", "TIMEZERO AT POINT  = early", "E.HD: HD field 'TIMEZERO AT POINT' = 'early'"),
    ("STEP SIZE USED     = 0.25", "STEP SIZE USED     = ?", "E.HD: HD field 'STEP SIZE USED' = '?'"),
    ("NUMBER OF STACKS   = 4", "NUMBER OF STACKS   = many", "E.HD: HD field 'NUMBER OF STACKS' = 'many'"),
    ("POSITION UNITS     = m", "POSITION UNITS     = Furlongs", "E.HD: unknown POSITION UNITS 'furlongs'"),
])
def test_every_header_error_names_the_header_file(tmp_path, old, new, message):
    p = write_dt1(tmp_path / "E")
    hd = p.with_suffix(".HD")
    assert old in hd.read_text()
    hd.write_text(hd.read_text().replace(old, new))
    with pytest.raises(FormatError) as e:
        read_dt1(p)
    assert str(e.value).startswith(message)


def test_optional_fields_left_out(tmp_path):
    """No time-zero point, stacks or position units: none, none, metres."""
    p = write_dt1(tmp_path / "O", step=0.5)
    hd = p.with_suffix(".HD")
    hd.write_text("\n".join(ln for ln in hd.read_text().splitlines()
                            if not ln.startswith(("TIMEZERO", "NUMBER OF STACKS", "POSITION UNITS"))))
    s = read_dt1(p)[0]
    assert s.metadata["header_timezero_point"] is None and s.metadata["stacks"] is None
    assert s.metadata["position_units"] == "m"
    np.testing.assert_allclose(s.positions_xyz[:, 0], 0.5 * np.arange(6))


def test_the_nul_look_ahead_ends_at_4096_bytes(tmp_path):
    from gpr3d.io.dt1 import read_hd

    hd = tmp_path / "N.HD"
    hd.write_bytes(b"1234\n" + b" " * 4090 + b"\x00")  # the NUL is byte 4095, the last one looked at
    with pytest.raises(FormatError, match="binary bytes"):
        read_hd(hd)
    hd.write_bytes(b"1234\n" + b" " * 4091 + b"\x00")  # byte 4096: not looked at
    assert read_hd(hd) == {}


def test_file_and_pair_errors_are_named(tmp_path):
    p = write_dt1(tmp_path / "S")
    p.write_bytes(p.read_bytes()[:100])
    with pytest.raises(FormatError, match="^S.DT1: file is 100 bytes, shorter than one 128-byte trace header$"):
        read_dt1(p)
    p.unlink()
    with pytest.raises(FormatError, match=r"^S.HD: no \.dt1 data file beside the header$"):
        read_dt1(p.with_suffix(".HD"))
    q = write_dt1(tmp_path / "Q")
    q.with_suffix(".HD").unlink()
    with pytest.raises(FormatError, match=r"^Q.DT1: no \.hd header beside the data \(pulseEKKO needs both\)$"):
        read_dt1(q)
    r = write_dt1(tmp_path / "R", n_traces=3, hd_traces=2)
    with pytest.raises(FormatError, match="^R.DT1: file holds 3 traces but the HD header says 2: header and data"):
        read_dt1(r)
    b = write_dt1(tmp_path / "B", n_traces=3, bad_trace=1)
    with pytest.raises(FormatError, match="^B.DT1: trace 1 header says 51 points, HD says 50"):
        read_dt1(b)


def _set_first_header(p, index, value):
    raw = bytearray(p.read_bytes())
    raw[4 * index : 4 * index + 4] = struct.pack("<f", value)
    p.write_bytes(bytes(raw))


def test_bytes_per_point_from_the_first_trace_header(tmp_path):
    """The first header's bytes-per-point word says 2 or 4; anything else (3, NaN) means the usual 2, and the word
    beside it does not matter."""
    p = write_dt1(tmp_path / "W", n_traces=2, n_points=8, bits=32)
    _set_first_header(p, 6, float("nan"))  # the time window word: not the one read
    s = read_dt1(p)[0]
    assert s.metadata["bytes_per_point"] == 4
    np.testing.assert_array_equal(s.data, expected_values(2, 8, 1, 32)[0].astype(np.float32))
    for junk in (3.0, float("nan"), float("inf"), 0.0):
        q = write_dt1(tmp_path / "J", n_traces=2, n_points=8, bits=16)
        _set_first_header(q, 5, junk)
        s = read_dt1(q)[0]
        assert s.metadata["bytes_per_point"] == 2, junk
        np.testing.assert_array_equal(s.data, expected_values(2, 8)[0].astype(np.float32))


def test_the_points_boundary(tmp_path):
    p = write_dt1(tmp_path / "L", n_traces=1, n_points=1_000_000)
    assert read_dt1(p)[0].n_samples == 1_000_000


def test_a_partial_last_trace_warns_once_unless_traces_are_missing_too(tmp_path):
    import warnings

    p = write_dt1(tmp_path / "P", n_traces=4, n_points=10, hd_traces=4)
    p.write_bytes(p.read_bytes()[:-10])  # the 4th trace cut: 3 whole traces and a part of the 4th the HD counts
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        s = read_dt1(p)[0]
    assert s.n_traces == 3
    assert [str(x.message) for x in w if issubclass(x.category, TruncatedRecordingWarning)] == [
        "P.DT1: recording ends mid-trace; dropped 1 partial trace (138 bytes), kept 3"]
    q = write_dt1(tmp_path / "Q", n_traces=4, n_points=10, hd_traces=5)
    q.write_bytes(q.read_bytes()[:-10])  # one trace missing besides the partial one: both said
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        read_dt1(q)
    msgs = [str(x.message) for x in w if issubclass(x.category, TruncatedRecordingWarning)]
    assert len(msgs) == 2 and msgs[1] == "Q.DT1: HD header says 5 traces, file holds 3; reading 3"
    r = write_dt1(tmp_path / "R", n_traces=3, n_points=10, hd_traces=4)  # whole traces, one fewer than the HD
    with pytest.warns(TruncatedRecordingWarning, match="HD header says 4 traces, file holds 3"):
        read_dt1(r)


def test_times_of_day_equal_or_small_are_kept(tmp_path):
    p = write_dt1(tmp_path / "T", n_traces=3, n_points=10)
    raw = bytearray(p.read_bytes())
    rec = 128 + 20
    for i, t in enumerate((0.25, 0.25, 0.5)):  # a repeat, and a last time under one second
        raw[i * rec + 92 : i * rec + 96] = struct.pack("<f", t)
    p.write_bytes(bytes(raw))
    s = read_dt1(p)[0]
    np.testing.assert_array_equal(s.timestamps_s, [0.25, 0.25, 0.5])


def test_no_positions_means_no_source(tmp_path):
    p = write_dt1(tmp_path / "Z", n_traces=3, n_points=10, step=0.0)
    s = read_dt1(p)[0]
    assert s.positions_xyz is None and s.metadata["positions_source"] is None and "gps" not in s.metadata


def test_a_gps_file_places_the_traces_and_is_described(tmp_path):
    p = write_dt1(tmp_path / "G", n_traces=3, n_points=10)
    p.with_suffix(".GPS").write_text(
        "$GPGGA,115959,5900.0000,N,01000.0000,E,1,08,1.0,10.0,M,,M,,*00\n"  # before any trace line: ignored
        "Trace #1 at position 0.0\n$GPGGA,120000,6000.0000,N,01000.0000,E,1,08,1.0,10.0*47\n"
        "$GPGGA,120000,6100.0000,N,01000.0000,E,1,08,1.0,10.0,M,,M,,*00\n"  # a second GGA of trace 1: ignored
        "Trace #3 at position 0.5\n$GPGGA,120001,6000.0600,N,01000.0000,E,1,08,1.0,12.0,M,,M,,*00\n")
    g = read_sns_gps(p.with_suffix(".GPS"))
    assert g["trace"].dtype == np.float64 and g["trace"].tolist() == [1.0, 3.0]
    assert g["alt"].tolist() == [10.0, 12.0]  # the first sentence ends at the altitude, with its checksum
    s = read_dt1(p)[0]
    assert s.metadata["positions_source"] == "pulseEKKO .GPS (local ENU metres about origin)"
    assert s.metadata["gps"] == {"file": "G.GPS", "fixes": 2, "origin_lat_lon_alt": [60.0, 10.0, 10.0]}
    north = s.positions_xyz[:, 1]
    assert north[0] == 0.0 and north[2] == pytest.approx(111.4, abs=0.5) and north[1] == pytest.approx(north[2] / 2)
