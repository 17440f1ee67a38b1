import numpy as np
import pytest

import gpr3d
from gpr3d.io.segy import write_segy
from tests.conftest import real_file

segyio = pytest.importorskip("segyio")


def test_segy_round_trip_through_segyio(tmp_path):
    s = gpr3d.read(real_file("gprpy_sns_50MHz/XLINE00.DT1"))
    out = tmp_path / "x.sgy"
    write_segy(s, out)
    with segyio.open(out, ignore_geometry=True) as f:
        assert f.tracecount == s.n_traces
        assert f.bin[segyio.BinField.Interval] == 800  # ps
        np.testing.assert_array_equal(segyio.tools.collect(f.trace[:]), s.data)
        h = f.header[10]
        assert h[segyio.TraceField.SourceX] == round(s.positions_xyz[10, 0] * 1000)
        assert h[segyio.TraceField.SourceGroupScalar] == -1000
        assert b"PICOSECONDS" in f.text[0]


def test_segy_rejects_huge_interval(tmp_path):
    s = gpr3d.Survey(data=np.zeros((2, 4)), dt_s=1e-7)
    with pytest.raises(gpr3d.InvalidDataError, match="16-bit"):
        write_segy(s, tmp_path / "y.sgy")
    assert not (tmp_path / "y.sgy").exists()


@pytest.mark.parametrize("name", ["gprpy_gssi_400MHz/FILE____032.DZT", "gprpy_sns_50MHz/XLINE00.DT1",
                                  "impdar_mala_500MHz/ten_col.rd3"])
def test_round_trip_of_a_real_file_is_exact(tmp_path, name):
    """A real recording to SEG-Y and back: samples, sample interval (93.75 ps for the DZT, which the 16-bit field
    would round to 94 ps, a 0.27 % time error), time zero, frequency, offset and positions (mm) all come back."""
    s = gpr3d.read(real_file(name))
    write_segy(s, tmp_path / "x.sgy")
    r = gpr3d.read(tmp_path / "x.sgy")
    assert r.metadata["format"] == "segy" and r.metadata["segy_revision"] == 2
    np.testing.assert_array_equal(r.data, s.data)
    assert r.dt_s == s.dt_s and r.t0_s == s.t0_s and r.offset_m == s.offset_m and r.frequency_hz == s.frequency_hz
    if s.positions_xyz is not None:
        np.testing.assert_allclose(r.positions_xyz, s.positions_xyz, atol=5e-4)  # millimetres in the file


def test_other_rev2_readers_get_the_exact_interval(tmp_path):
    """Without gpr3d's textual header (another program's reader), the interval comes from SEG-Y rev 2's extended
    field (bytes 3281-3288), not the rounded 16-bit one."""
    import struct

    s = gpr3d.Survey(data=np.arange(24, dtype=np.float32).reshape(3, 8), dt_s=93.75e-12)
    write_segy(s, tmp_path / "x.sgy")
    raw = (tmp_path / "x.sgy").read_bytes()
    assert struct.unpack(">d", raw[3280:3288])[0] == pytest.approx(93.75, rel=1e-12)
    assert struct.unpack(">h", raw[3216:3218])[0] == 94 and raw[3500] == 2
    with segyio.open(tmp_path / "x.sgy", "r+", ignore_geometry=True) as f:
        f.text[0] = segyio.tools.create_text_header({1: "SOME OTHER PROGRAM, SAMPLE INTERVAL IN PICOSECONDS"})
    r = gpr3d.read(tmp_path / "x.sgy")
    assert r.metadata["written_by_gpr3d"] is False and r.dt_s == pytest.approx(93.75e-12, rel=1e-12)
    np.testing.assert_array_equal(r.data, s.data)


def test_a_foreign_segy_reads_its_interval_in_picoseconds_unless_told(tmp_path):
    """A rev 1 file from another program (IBM floats, no coordinates, interval field 100): 0.1 ns by the GPR
    convention, 0.1 us if the caller says microseconds... which is no GPR interval: refused in one line."""
    spec = segyio.spec()
    spec.format, spec.samples, spec.tracecount = 1, np.arange(50) * 0.1, 4
    data = np.random.default_rng(0).standard_normal((4, 50)).astype(np.float32)
    with segyio.create(tmp_path / "other.segy", spec) as f:
        f.bin.update({segyio.BinField.Interval: 100, segyio.BinField.Samples: 50, segyio.BinField.Format: 1})
        for i in range(4):
            f.header[i] = {segyio.TraceField.TRACE_SAMPLE_COUNT: 50, segyio.TraceField.TRACE_SAMPLE_INTERVAL: 100}
        f.trace = data
    r = gpr3d.read(tmp_path / "other.segy")
    assert r.dt_s == pytest.approx(1e-10) and r.positions_xyz is None and r.metadata["dt_unit"] == "ps"
    np.testing.assert_allclose(r.data, data, rtol=1e-6)  # IBM floats hold float32 to about 1e-7
    assert gpr3d.read(tmp_path / "other.segy", dt_unit="ns").dt_s == pytest.approx(1e-7)
    with pytest.raises(gpr3d.GPR3DError, match="no GPR interval"):
        gpr3d.read(tmp_path / "other.segy", dt_unit="us")


def test_a_truncated_segy_is_one_line(tmp_path):
    s = gpr3d.Survey(data=np.ones((5, 16), np.float32), dt_s=1e-10)
    write_segy(s, tmp_path / "x.sgy")
    cut = tmp_path / "cut.sgy"
    cut.write_bytes((tmp_path / "x.sgy").read_bytes()[:3600 + 240 + 20])
    with pytest.raises(gpr3d.GPR3DError, match="cut.sgy"):
        gpr3d.read(cut)
