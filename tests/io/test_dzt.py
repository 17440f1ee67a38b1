import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import gpr3d
from gpr3d.core.errors import FormatError, TruncatedRecordingWarning
from gpr3d.io.dzt import read_dzg, read_dzt, read_dzt_header
from tests.conftest import real_file
from tests.io.makers import expected_values, write_dzt


# ---------------------------------------------------------------- real files: header facts
def test_gssi_400mhz_header_facts():
    s = gpr3d.read(real_file("gprpy_gssi_400MHz/FILE____032.DZT"))
    # facts from ../shared/data/real/README.md
    assert s.shape == (1040, 512)
    assert s.time_window_s == pytest.approx(48e-9, rel=1e-9, abs=0)
    assert s.frequency_hz == 400e6
    assert s.eps_r == 6.0
    assert s.metadata["bits"] == 16
    assert s.metadata["scans_per_m"] == 50.0
    assert s.metadata["created"].startswith("2017-")
    # survey wheel: 50 scans/m -> 1039 steps of 2 cm
    assert s.distances_m[-1] == pytest.approx(1039 / 50)


def test_marks_are_read_and_place_the_traces_as_the_wheel_does():
    """FILE____032.DZT carries a mark every 100 scans in its traces' mark word; its header says 50 scans per
    metre, so marks every 2 m place every trace where the survey wheel does (two independent records)."""
    from gpr3d.core.gridsurvey import place_by_marks

    s = gpr3d.read(real_file("gprpy_gssi_400MHz/FILE____032.DZT"))
    assert s.metadata["marks"] == list(range(0, 1001, 100))
    placed = place_by_marks(s, 2.0)
    np.testing.assert_allclose(placed.positions_xyz, s.positions_xyz, atol=1e-9)
    assert placed.metadata["positions_source"] == "marks every 2 m"
    # the SIR-4000 file has no marks set
    assert gpr3d.read(real_file("impdar_gssi_sir4000/test_gssi.DZT")).metadata["marks"] == []


def test_sir4000_32bit_large_header():
    p = real_file("impdar_gssi_sir4000/test_gssi.DZT")
    hdr = read_dzt_header(p)
    assert hdr["data_offset"] == 131072
    assert hdr["bits"] == 32
    s = gpr3d.read(p)
    assert s.shape == (345, 2048)
    assert s.time_window_s == pytest.approx(2300e-9, rel=1e-9, abs=0)
    assert s.frequency_hz == 200e6  # antenna model 5106
    assert s.metadata["antenna"] == "5106"
    # DZG present but holds no GPS fix: no invented positions
    assert s.metadata["gps"]["fixes"] == 0
    assert s.metadata["gps"]["records"] > 0
    assert s.positions_xyz is None


@pytest.mark.parametrize("rel", ["gprpy_gssi_400MHz/FILE____032.DZT", "impdar_gssi_sir4000/test_gssi.DZT"])
def test_samples_match_readgssi(rel, tmp_path):
    """Cross-check every sample against readgssi, an independent reader."""
    readgssi_dzt = pytest.importorskip("readgssi.dzt")
    src = real_file(rel)
    copy = tmp_path / src.name  # without its DZG: readgssi fails on DZGs without a fix
    shutil.copy(src, copy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hdr, arrs, _ = readgssi_dzt.readdzt(str(copy))
    ref = np.asarray(arrs[0], dtype=np.float64).T  # readgssi: (samples, traces), raw integers
    zero = {16: 32768.0, 8: 128.0, 32: 0.0}[hdr["rh_bits"]]
    s = gpr3d.read(src)
    # readgssi drops the first rh_zero samples of 32-bit files (rh_zero = 1 in the SIR-4000 file)
    crop = s.n_samples - ref.shape[1]
    assert crop == (hdr["rh_zero"] if hdr["rh_bits"] == 32 else 0)
    assert s.n_traces == ref.shape[0]
    assert hdr["rhf_range"] * 1e-9 == pytest.approx(s.time_window_s, rel=1e-9, abs=0)
    # samples 0 and 1 of each GSSI trace are a scan counter and a mark word; gpr3d replaces them
    np.testing.assert_array_equal(s.data[:, crop + 2 :], (ref[:, 2:] - zero).astype(np.float32))
    np.testing.assert_array_equal(s.data[:, 0], s.data[:, 2])


# ---------------------------------------------------------------- synthetic files: exact values
@pytest.mark.parametrize("bits", [8, 16, 32])
@pytest.mark.parametrize("nchan", [1, 2, 3])
def test_bits_and_channels(tmp_path, bits, nchan):
    p = write_dzt(tmp_path / "x.DZT", n_traces=9, n_samples=32, n_channels=nchan, bits=bits,
                  antennas=("5103", "3101", "400MHz"))
    surveys = gpr3d.read_all(p)
    assert len(surveys) == nchan
    want = expected_values(9, 32, nchan, bits)
    for ch, s in enumerate(surveys):
        assert s.metadata["channel"] == ch
        np.testing.assert_array_equal(s.data[:, 2:], want[ch][:, 2:].astype(np.float32))
    assert [s.frequency_hz for s in surveys] == [400e6, 900e6, 400e6][:nchan]
    assert surveys[0].metadata["created"] == "2021-06-15T10:20:30"
    assert surveys[0].dt_s == pytest.approx(20e-9 / 32, rel=1e-9, abs=0)
    assert surveys[0].timestamps_s[3] == pytest.approx(3 / 50.0, rel=1e-9, abs=0)


def test_big_header_offset(tmp_path):
    p = write_dzt(tmp_path / "big.DZT", rh_data=128)
    assert read_dzt_header(p)["data_offset"] == 131072
    np.testing.assert_array_equal(gpr3d.read(p).data[:, 2:], expected_values(7, 64)[0][:, 2:])


def test_truncated_mid_trace_warns_and_keeps_whole_traces(tmp_path):
    p = write_dzt(tmp_path / "cut.DZT", n_traces=5, n_samples=16, extra_bytes=10)
    with pytest.warns(TruncatedRecordingWarning, match="dropped 1 partial trace"):
        s = gpr3d.read(p)
    assert s.n_traces == 5


@pytest.mark.parametrize(
    "patch, message",
    [
        ((6, b"\x0c\x00"), "12 bits per sample"),
        ((52, b"\x00\x00"), "0 channels"),
        ((4, b"\x01\x00"), "1 samples per trace"),
        ((26, b"\x00\x00\xc0\x7f"), "range"),  # NaN range
        ((2, b"\xff\x00"), "beyond the end of the file"),
    ],
)
def test_corrupt_headers_name_the_problem(tmp_path, patch, message):
    p = write_dzt(tmp_path / "bad.DZT")
    raw = bytearray(p.read_bytes())
    off, b = patch
    raw[off : off + len(b)] = b
    p.write_bytes(bytes(raw))
    with pytest.raises(FormatError, match=message) as info:
        read_dzt(p)
    assert str(info.value).startswith("bad.DZT: ")


def test_header_only_file_has_no_traces(tmp_path):
    p = write_dzt(tmp_path / "empty.DZT", n_traces=0)
    with pytest.raises(FormatError, match="no complete trace"):
        gpr3d.read(p)


def test_dzg_with_fixes_gives_local_positions(tmp_path):
    p = write_dzt(tmp_path / "gps.DZT", n_traces=11)
    # two fixes 0.001' of latitude apart (1.853 m north) at scans 0 and 10
    (tmp_path / "gps.DZG").write_text(
        "$GSSIS,0,-1\n$GPGGA,120000,4739.0000,N,12218.0000,W,1,08,1.0,10.0,M,,M,,*00\n\n"
        "$GSSIS,10,-1\n$GPGGA,120001,4739.0010,N,12218.0000,W,1,08,1.0,12.0,M,,M,,*00\n\n"
        "$GSSIS,5,-1\n$GPGGA,120002,garbage\n"
    )
    s = gpr3d.read(p)
    assert s.metadata["gps"]["fixes"] == 2
    north = s.positions_xyz[:, 1]
    assert north[-1] == pytest.approx(0.001 / 60 * np.pi / 180 * 6_366_000, rel=3e-3)
    assert np.allclose(s.positions_xyz[:, 0], 0, atol=1e-9)
    assert s.positions_xyz[5, 2] == pytest.approx(1.0)  # altitude halfway
    g = read_dzg(tmp_path / "gps.DZG")
    assert g["malformed"] == 1


def test_partial_gps_dzg_is_tolerated():
    g = read_dzg(real_file("impdar_gssi_sir4000/test_gssi_partialgps.DZG"))
    assert g["records"] >= 10 and g["scan"].size == 0  # no fix, broken sentences skipped


# ---------------------------------------------------------------- the header field by field

import struct  # noqa: E402

from gpr3d.io.dzt import _antenna_mhz, _decode_date, is_dzt  # noqa: E402


def _patched(p, *patches):
    raw = bytearray(p.read_bytes())
    for off, b in patches:
        raw[off : off + len(b)] = b
    p.write_bytes(bytes(raw))
    return p


def _packed(year, month, day, hour, minute, sec):
    return ((sec // 2) | (minute << 5) | (hour << 11) | (day << 16) | (month << 21) | ((year - 1980) << 25)).to_bytes(
        4, "little")


def test_packed_dates():
    assert _decode_date(_packed(2019, 12, 31, 23, 59, 58)) == "2019-12-31T23:59:58"
    assert _decode_date(_packed(1980, 1, 1, 0, 0, 0)) == "1980-01-01T00:00:00"
    assert _decode_date(_packed(2107, 2, 3, 4, 5, 7)) == "2107-02-03T04:05:06"  # two-second steps, 7 bits of year
    assert _decode_date(b"\0\0\0\0") is None  # not set
    assert _decode_date(_packed(2020, 13, 1, 0, 0, 0)) is None  # month 13
    assert _decode_date(_packed(2020, 2, 30, 0, 0, 0)) is None  # 30 February


@pytest.mark.parametrize("name, mhz", [
    ("5103", 400.0), ("  3101A ", 900.0), ("SS MINI", 1600.0), ("62300XT", 2300.0),
    ("400MHz", 400.0), ("GSSI 270 MHz", 270.0), ("1.6 GHz", 1600.0), ("2.7ghz palm", 2700.0),
    ("51600x3", 1600.0), ("3207xAP", 100.0),  # a known model before an 'x' suffix
    ("model 5103", None), ("", None), ("custom", None), ("99999x", None),
])
def test_antenna_names_to_frequencies(name, mhz):
    assert _antenna_mhz(name) == mhz


def test_every_header_field(tmp_path):
    p = write_dzt(tmp_path / "h.DZT", n_traces=3, n_samples=16, sps=32.0, spm=40.0, eps_r=4.5,
                  antennas=("3101",))
    _patched(p, (18, struct.pack("<f", 2.5)), (22, struct.pack("<f", 7.25)), (36, _packed(2022, 3, 4, 5, 6, 8)),
             (113, bytes([0b10111_001])), (114, b"LINE007.DZT\0"))
    h = read_dzt_header(p)
    assert h["tag"] == 0x00FF and h["data_offset"] == 1024 and h["n_samples"] == 16 and h["bits"] == 16
    assert h["zero"] == 0x8000 and h["n_channels"] == 1 and h["range_ns"] == 20.0
    assert (h["scans_per_s"], h["scans_per_m"], h["m_per_mark"], h["position_ns"]) == (32.0, 40.0, 2.5, 7.25)
    assert h["eps_r"] == 4.5 and h["antennas"] == ["3101"]
    assert h["created"] == "2021-06-15T10:20:30" and h["modified"] == "2022-03-04T05:06:08"
    assert h["system_code"] == 0b10111 and h["file_name"] == "LINE007.DZT"
    assert h["file_bytes"] == 1024 + 3 * 16 * 2
    s = read_dzt(p)[0]
    m = s.metadata
    assert (m["format"], m["channel"], m["n_channels"], m["bits"], m["antenna"]) == ("dzt", 0, 1, 16, "3101")
    assert m["range_s"] == pytest.approx(20e-9, rel=1e-9, abs=0) and m["position_s"] == pytest.approx(7.25e-9, rel=1e-9, abs=0)
    assert (m["scans_per_s"], m["scans_per_m"], m["system_code"], m["data_offset"]) == (32.0, 40.0, 23, 1024)
    assert m["header_samples_replaced"] == 2 and m["path"].endswith("h.DZT") and "gps" not in m
    assert m["positions_source"] == "survey wheel (header scans per metre), along world x"
    np.testing.assert_allclose(s.positions_xyz[:, 0], [0.0, 0.025, 0.05])
    np.testing.assert_allclose(s.timestamps_s, [0.0, 1 / 32, 2 / 32])
    assert s.eps_r == 4.5 and s.frequency_hz == 900e6 and s.dt_s == pytest.approx(20e-9 / 16, rel=1e-9, abs=0)


@pytest.mark.parametrize("eps, kept", [(1.0, True), (100.0, True), (0.99, False), (100.5, False),
                                       (float("nan"), False), (float("inf"), False)])
def test_header_eps_r_only_when_plausible(tmp_path, eps, kept):
    p = write_dzt(tmp_path / "e.DZT", eps_r=eps)
    assert read_dzt_header(p)["eps_r"] == (eps if kept else None)


@pytest.mark.parametrize("field, off", [("scans_per_s", 10), ("scans_per_m", 14)])
@pytest.mark.parametrize("value", [0.0, -5.0, float("nan"), float("inf")])
def test_rates_not_positive_and_finite_are_left_out(tmp_path, field, off, value):
    p = _patched(write_dzt(tmp_path / "r.DZT"), (off, struct.pack("<f", value)))
    h = read_dzt_header(p)
    assert h[field] is None
    s = read_dzt(p)[0]
    if field == "scans_per_s":
        assert s.timestamps_s is None
    else:
        assert s.positions_xyz is None and s.metadata["positions_source"] is None


def test_mark_and_position_fields_not_finite(tmp_path):
    p = _patched(write_dzt(tmp_path / "m.DZT"), (18, struct.pack("<f", float("nan"))),
                 (22, struct.pack("<f", float("inf"))))
    h = read_dzt_header(p)
    assert h["m_per_mark"] is None and h["position_ns"] is None
    assert read_dzt(p)[0].metadata["position_s"] is None
    p = _patched(p, (18, struct.pack("<f", -1.0)), (22, struct.pack("<f", -3.0)))  # negative but finite: kept
    assert (read_dzt_header(p)["m_per_mark"], read_dzt_header(p)["position_ns"]) == (-1.0, -3.0)


@pytest.mark.parametrize("patch, message", [
    ((52, struct.pack("<H", 17)), "header gives 17 channels (expected 1..16): not a DZT file or corrupt"),
    ((6, struct.pack("<H", 24)), "header gives 24 bits per sample (expected 8, 16 or 32): not a DZT file or corrupt"),
    ((26, struct.pack("<f", 2e6)), "header range 2e+06 ns is implausible"),
    ((26, struct.pack("<f", 0.0)), "header field range (ns) = 0.0 is not a positive number"),
    ((2, struct.pack("<H", 0)), "data offset 0 lies inside the 1 channel header(s)"),
])
def test_more_corrupt_headers(tmp_path, patch, message):
    p = _patched(write_dzt(tmp_path / "bad.DZT"), patch)
    with pytest.raises(FormatError) as e:
        read_dzt_header(p)
    assert str(e.value) == f"bad.DZT: {message}"


def test_the_boundaries_of_the_header(tmp_path):
    p = write_dzt(tmp_path / "b.DZT", n_samples=2, range_ns=1e6)  # 2 samples, a 1 ms range: allowed
    s = read_dzt(p)[0]
    assert s.n_samples == 2 and s.time_window_s == pytest.approx(1e-3, rel=1e-9, abs=0)
    # two samples: nothing replaced, no mark word read
    assert s.metadata["header_samples_replaced"] == 0 and s.metadata["marks"] == []
    np.testing.assert_array_equal(s.data, expected_values(7, 2)[0].astype(np.float32))
    p = write_dzt(tmp_path / "c.DZT", n_channels=16, antennas=("5103",), n_traces=2, n_samples=4)
    assert len(read_dzt(p)) == 16
    short = tmp_path / "short.DZT"
    short.write_bytes(b"\0" * 1023)
    with pytest.raises(FormatError, match="short.DZT: file is 1023 bytes, shorter than one 1024-byte DZT header"):
        read_dzt_header(short)
    two = write_dzt(tmp_path / "two.DZT", n_channels=2, n_traces=0)
    two.write_bytes(two.read_bytes()[:1500])
    with pytest.raises(FormatError, match="two.DZT: file is 1500 bytes, shorter than 2 channel headers"):
        read_dzt_header(two)
    # rh_data of 1024 or more means 'after the channel headers'
    p = write_dzt(tmp_path / "d.DZT", n_channels=2, rh_data=1024)
    assert read_dzt_header(p)["data_offset"] == 2048
    assert read_dzt_header(write_dzt(tmp_path / "e.DZT", rh_data=1023, n_traces=1))["data_offset"] == 1023 * 1024


def test_the_mark_word_and_the_binary_zero(tmp_path):
    p = write_dzt(tmp_path / "k.DZT", n_traces=6, n_samples=8, n_channels=2, bits=8)
    raw = bytearray(p.read_bytes())
    for tr in range(6):  # every mark word (sample 1) clear
        raw[2048 + tr * 16 + 1] = raw[2048 + tr * 16 + 8 + 1] = 0
    for tr in (1, 4):  # then channel 0's set on scans 1 and 4; channel 1's on scan 2 (not read)
        raw[2048 + tr * 16 + 1] = 0x55
    raw[2048 + 2 * 16 + 8 + 1] = 0x55
    p.write_bytes(bytes(raw))
    surveys = read_dzt(p)
    assert surveys[0].metadata["marks"] == [1, 4] == surveys[1].metadata["marks"]
    want = expected_values(6, 8, 2, 8)
    for ch, s in enumerate(surveys):
        np.testing.assert_array_equal(s.data[:, 2:], want[ch][:, 2:].astype(np.float32))  # 128 taken off
        np.testing.assert_array_equal(s.data[:, 0], s.data[:, 2])
        np.testing.assert_array_equal(s.data[:, 1], s.data[:, 2])


def test_is_dzt(tmp_path):
    p = write_dzt(tmp_path / "a.DZT", n_traces=2, n_samples=16)
    assert is_dzt(p)
    other = tmp_path / "a.bin"
    other.write_bytes(p.read_bytes())
    assert is_dzt(other)  # another suffix: a whole trace after the header is enough
    other.write_bytes(p.read_bytes()[: 1024 + 31])  # one byte short of a 32-byte trace
    assert not is_dzt(other)
    other.write_bytes(p.read_bytes()[: 1024 + 32])
    assert is_dzt(other)
    named = tmp_path / "b.dzt"
    named.write_bytes(p.read_bytes()[:1024])  # a .dzt suffix: the header alone is enough
    assert is_dzt(named)
    junk = tmp_path / "junk.dzt"
    junk.write_bytes(b"\xff" * 4096)
    assert not is_dzt(junk)


def test_dzg_records_fixes_and_sentences(tmp_path):
    g = tmp_path / "t.DZG"
    g.write_text(
        "$GPGGA,115959,4739.0000,N,12218.0000,W,1,08,1.0,9.0,M,,M,,*00\n"  # before any $GSSIS: ignored
        "$GSSIS,3,-1\n$GPRMC,120000,A,4739.0000,N,12218.0000,W,0.0,0.0,010120,,*00\n"  # not GGA: ignored
        "$GNGGA,120000,4739.0000,S,12218.0000,E,2,08,1.0,,M,,M,,*00\n"  # any talker; no altitude: 0
        "$GNGGA,120000,4740.0000,N,12218.0000,E,2,08,1.0,5.0,M,,M,,*00\n"  # a second GGA of the record: ignored
        "\n   \n"
        "$GSSIS,7,-1\n$GPGGA,120001,4739.5000,N,00030.0000,W,0,08,1.0,11.0,M,,M,,*00\n"  # quality 0: no fix
        "$GSSIS,9,-1\n$GPGGA,120002,4739.5000,N\n"  # cut short: malformed
        "$GSSIS,12,-1\nGPGGA,120002,4739.5000,N,00030.0000,W,1,08,1.0,11.0,M,,M,,*00\n"  # no '$': ignored
        "$GSSIS,15,-1\n$GPGGA,120003,4739.5000,N,00030.0000,W,1,08,1.0,11.5,M,,M,,*00\n"
    )
    d = read_dzg(g)
    assert d["records"] == 5 and d["malformed"] == 1
    np.testing.assert_array_equal(d["scan"], [3.0, 15.0])
    assert d["scan"].dtype == np.float64
    np.testing.assert_allclose(d["lat"], [-(47 + 39 / 60), 47 + 39.5 / 60])
    np.testing.assert_allclose(d["lon"], [122 + 18 / 60, -0.5])
    np.testing.assert_allclose(d["alt"], [0.0, 11.5])


def test_the_dzg_is_read_only_when_asked_and_needs_two_fixes(tmp_path):
    p = write_dzt(tmp_path / "g.DZT", n_traces=11, spm=50.0)
    dzg = tmp_path / "g.DZG"
    dzg.write_text("$GSSIS,0,-1\n$GPGGA,120000,4739.0000,N,12218.0000,W,1,08,1.0,10.0,M,,M,,*00\n"
                   "$GSSIS,10,-1\n$GPGGA,120001,4739.0010,N,12218.0000,W,1,08,1.0,12.0,M,,M,,*00\n")
    s = read_dzt(p)[0]
    assert s.metadata["positions_source"] == "DZG GPS (local ENU metres about origin)"
    assert s.metadata["gps"] == {"file": "g.DZG", "records": 2, "fixes": 2, "malformed": 0,
                                 "origin_lat_lon_alt": pytest.approx([47.65, -(122 + 18 / 60), 10.0])}
    off = read_dzt(p, gps=False)[0]  # the wheel instead, and no gps block
    assert "gps" not in off.metadata and off.metadata["positions_source"].startswith("survey wheel")
    np.testing.assert_allclose(off.positions_xyz[:, 0], np.arange(11) / 50.0)
    dzg.write_text("$GSSIS,0,-1\n$GPGGA,120000,4739.0000,N,12218.0000,W,1,08,1.0,10.0,M,,M,,*00\n")
    one = read_dzt(p)[0]  # one fix: the wheel places the traces; the DZG is still described
    assert one.metadata["positions_source"].startswith("survey wheel")
    assert one.metadata["gps"] == {"file": "g.DZG", "records": 1, "fixes": 1, "malformed": 0}


def test_more_header_edges(tmp_path):
    # a range just over 1e6 ns is refused
    p = _patched(write_dzt(tmp_path / "r.DZT"), (26, struct.pack("<f", 1000000.5)))
    with pytest.raises(FormatError, match="header range 1e\\+06 ns is implausible"):
        read_dzt_header(p)
    # two channels whose data would start inside the second channel's header
    p = write_dzt(tmp_path / "two.DZT", n_channels=2, rh_data=1)
    with pytest.raises(FormatError, match="^two.DZT: data offset 1024 lies inside the 2 channel header\\(s\\)$"):
        read_dzt_header(p)
    # a 14-character antenna name, and a 12-character file name, each filling its field up to the next byte
    p = _patched(write_dzt(tmp_path / "n.DZT"), (98, b"ABCDEFGHIJKLMN"), (112, b"Z"), (114, b"FILE0001.DZT"),
                 (126, b"Q"), (36, _packed(2022, 3, 4, 5, 6, 8)), (40, b"\x7f"))
    h = read_dzt_header(p)
    assert h["antennas"] == ["ABCDEFGHIJKLMN"] and h["file_name"] == "FILE0001.DZT"
    assert h["modified"] == "2022-03-04T05:06:08"  # four bytes only
    # rates below one per second or metre are still rates
    p = _patched(write_dzt(tmp_path / "s.DZT"), (10, struct.pack("<f", 0.5)), (14, struct.pack("<f", 0.25)))
    h = read_dzt_header(p)
    assert (h["scans_per_s"], h["scans_per_m"]) == (0.5, 0.25)


def test_three_samples_still_carry_a_counter_and_a_mark_word(tmp_path):
    p = write_dzt(tmp_path / "t.DZT", n_traces=4, n_samples=3)
    raw = bytearray(p.read_bytes())
    for tr in range(4):  # the mark word (sample 1, 16 bits) clear but on scan 2
        raw[1024 + tr * 6 + 2 : 1024 + tr * 6 + 4] = (5 if tr == 2 else 0).to_bytes(2, "little")
    p.write_bytes(bytes(raw))
    s = read_dzt(p)[0]
    assert s.metadata["marks"] == [2] and s.metadata["header_samples_replaced"] == 2
    np.testing.assert_array_equal(s.data[:, 0], s.data[:, 2])
    np.testing.assert_array_equal(s.data[:, 1], s.data[:, 2])


def test_is_dzt_counts_every_channel_of_a_trace(tmp_path):
    p = write_dzt(tmp_path / "a.DZT", n_traces=1, n_samples=16, n_channels=2, rh_data=2)
    other = tmp_path / "a.bin"
    other.write_bytes(p.read_bytes())  # exactly one scan: 2 channels x 16 samples x 2 bytes
    assert is_dzt(other)
    other.write_bytes(p.read_bytes()[:-1])
    assert not is_dzt(other)


def test_dzg_counts_every_broken_sentence_and_reads_a_short_one(tmp_path):
    g = tmp_path / "b.DZG"
    g.write_text("$GSSIS,1,-1\n$GPGGA,1,4739.0\n$GSSIS,2,-1\n$GPGGA,1,4739.0,N\n"
                 "$GSSIS,3,-1\n$GPGGA,120000,4739.0000,N,12218.0000,W,1,08,1.0,10.5*47\n")
    d = read_dzg(g)
    assert d["malformed"] == 2 and d["scan"].tolist() == [3.0] and d["alt"].tolist() == [10.5]


def test_an_unreadable_dzg_is_left_out(tmp_path):
    p = write_dzt(tmp_path / "g.DZT", spm=50.0)
    (tmp_path / "g.DZG").write_bytes(b"")  # empty: the reader refuses it, the DZT is read without it
    s = read_dzt(p)[0]
    assert "gps" not in s.metadata and s.metadata["positions_source"].startswith("survey wheel")


def test_a_file_that_shrinks_while_read(tmp_path, monkeypatch):
    p = write_dzt(tmp_path / "k.DZT")
    real = np.fromfile
    monkeypatch.setattr(np, "fromfile", lambda *a, **k: real(*a, **k)[:-1])
    with pytest.raises(FormatError) as e:
        read_dzt(p)
    assert str(e.value) == "k.DZT: file shrank while being read"


def test_a_channel_count_the_file_does_not_hold_is_refused(tmp_path):
    # issue 31: the real one-channel DZT with its header's channel count set to 16 once read 16 "channels" whose
    # headers were sample bytes (and convert wrote them out)
    raw = bytearray((Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT").read_bytes())
    raw[52:54] = struct.pack("<H", 16)
    p = tmp_path / "sixteen.DZT"
    p.write_bytes(bytes(raw))
    with pytest.raises(FormatError) as e:
        read_dzt(p)
    assert str(e.value).startswith("sixteen.DZT: header gives 16 channels, but bytes 1024..2047 hold no header of "
                                   "channel 2 (")
    assert str(e.value).endswith("): the file holds fewer channels, or is corrupt")
    # the same file with its true count reads, and written two-channel files still do
    raw[52:54] = struct.pack("<H", 1)
    p.write_bytes(bytes(raw))
    assert len(read_dzt(p)) == 1
    two = write_dzt(tmp_path / "two.DZT", n_channels=2, n_traces=3, n_samples=8)
    head = bytearray(two.read_bytes())
    head[1024 + 6 : 1024 + 8] = struct.pack("<H", 7)  # channel 2's bits per sample: 7
    two.write_bytes(bytes(head))
    with pytest.raises(FormatError, match=r"bytes 1024\.\.2047 hold no header of channel 2 \(7 bits, 8 samples"):
        read_dzt(two)


@pytest.mark.parametrize("at, value, ok", [
    (4, struct.pack("<H", 1), False), (4, struct.pack("<H", 2), True),  # channel 2's samples: 1 refused, 2 taken
    (26, struct.pack("<f", float("nan")), False), (26, struct.pack("<f", 0.0), False),
    (26, struct.pack("<f", 0.5), True),  # its range: positive and finite, any size
    (6, struct.pack("<H", 16), True), (6, struct.pack("<H", 12), False),
])
def test_what_a_channel_header_must_hold(tmp_path, at, value, ok):
    p = write_dzt(tmp_path / "two.DZT", n_channels=2, n_traces=3, n_samples=8)
    raw = bytearray(p.read_bytes())
    raw[1024 + at : 1024 + at + len(value)] = value
    p.write_bytes(bytes(raw))
    if ok:
        assert len(read_dzt(p)) == 2
    else:
        with pytest.raises(FormatError, match=r"hold no header of channel 2"):
            read_dzt(p)


def test_a_dzt_of_many_blocks_reads_as_one(tmp_path):
    """Traces of 4 MiB (16 channels of 65,535 32-bit samples): the reader's 32 MiB blocks hold 7 of them, so 9 traces
    take two blocks, the second a part one; every sample as written, the marks of both blocks."""
    p = write_dzt(tmp_path / "big.DZT", n_traces=9, n_samples=65535, n_channels=16, bits=32)
    surveys = read_dzt(p)
    want = expected_values(9, 65535, 16, 32)
    for ch in (0, 7, 15):
        np.testing.assert_array_equal(surveys[ch].data[:, 2:], want[ch][:, 2:].astype(np.float32))
    assert surveys[0].metadata["marks"] == np.nonzero(want[0][:, 1])[0].tolist()
