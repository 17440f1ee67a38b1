import shutil
import warnings

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
    assert s.time_window_s == pytest.approx(48e-9)
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
    assert s.time_window_s == pytest.approx(2300e-9)
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
    assert hdr["rhf_range"] * 1e-9 == pytest.approx(s.time_window_s)
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
    assert surveys[0].dt_s == pytest.approx(20e-9 / 32)
    assert surveys[0].timestamps_s[3] == pytest.approx(3 / 50.0)


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
