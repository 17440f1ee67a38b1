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
    assert struct.unpack(">d", raw[3280:3288])[0] == pytest.approx(93.75, rel=1e-12, abs=0)
    assert struct.unpack(">h", raw[3216:3218])[0] == 94 and raw[3500] == 2
    with segyio.open(tmp_path / "x.sgy", "r+", ignore_geometry=True) as f:
        f.text[0] = segyio.tools.create_text_header({1: "SOME OTHER PROGRAM, SAMPLE INTERVAL IN PICOSECONDS"})
    r = gpr3d.read(tmp_path / "x.sgy")
    assert r.metadata["written_by_gpr3d"] is False and r.dt_s == pytest.approx(93.75e-12, rel=1e-12, abs=0)
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
    assert r.dt_s == pytest.approx(1e-10, rel=1e-9, abs=0) and r.positions_xyz is None and r.metadata["dt_unit"] == "ps"
    np.testing.assert_allclose(r.data, data, rtol=1e-6)  # IBM floats hold float32 to about 1e-7
    assert gpr3d.read(tmp_path / "other.segy", dt_unit="ns").dt_s == pytest.approx(1e-7, rel=1e-9, abs=0)
    with pytest.raises(gpr3d.GPR3DError, match="no GPR interval"):
        gpr3d.read(tmp_path / "other.segy", dt_unit="us")


def test_a_truncated_segy_is_one_line(tmp_path):
    s = gpr3d.Survey(data=np.ones((5, 16), np.float32), dt_s=1e-10)
    write_segy(s, tmp_path / "x.sgy")
    cut = tmp_path / "cut.sgy"
    cut.write_bytes((tmp_path / "x.sgy").read_bytes()[:3600 + 240 + 20])
    with pytest.raises(gpr3d.GPR3DError, match="cut.sgy"):
        gpr3d.read(cut)


def _foreign(path, *, n=4, ns=40, endian="big", fmt=5, text="SOME OTHER PROGRAM", bin_interval=100,
             trace_interval=100, heads=None, rev=None, ext=None):
    """A SEG-Y file as another program might write it; ``heads``: per-trace header fields; ``rev``/``ext``: the
    revision byte and extended interval written by hand (SEG-Y rev 2) in the file's byte order."""
    import struct

    spec = segyio.spec()
    spec.format, spec.samples, spec.tracecount, spec.endian = fmt, np.arange(ns) * 0.1, n, endian
    data = (np.arange(n * ns, dtype=np.float32).reshape(n, ns) - 7.0) / 4.0
    with segyio.create(str(path), spec) as f:
        f.text[0] = segyio.tools.create_text_header({1: text})
        f.bin.update({segyio.BinField.Interval: bin_interval, segyio.BinField.Samples: ns,
                      segyio.BinField.Format: fmt})
        for i in range(n):
            h = {segyio.TraceField.TRACE_SAMPLE_COUNT: ns, segyio.TraceField.TRACE_SAMPLE_INTERVAL: trace_interval}
            h.update((heads or {}).get(i, {}))
            f.header[i] = h
        f.trace = data
    if rev is not None or ext is not None:
        o = ">" if endian == "big" else "<"
        with open(path, "r+b") as raw:
            if ext is not None:
                raw.seek(3280)
                raw.write(struct.pack(o + "d", ext))
            if rev is not None:
                raw.seek(3500)
                raw.write(struct.pack(o + "H", rev << 8))  # major byte first in the field, minor 0
    return data


def test_foreign_files_by_byte_order_revision_and_unit(tmp_path):
    """Little-endian rev 2 with an extended interval of 93.75 (ps); a rev 1 file whose extended bytes hold
    garbage is read from the 16-bit field; 'NANOSECOND' in another program's text means nanoseconds."""
    p = tmp_path / "le.sgy"
    data = _foreign(p, endian="little", rev=2, ext=93.75, bin_interval=94)
    r = gpr3d.read(p)
    assert r.dt_s == pytest.approx(93.75e-12, rel=1e-12, abs=0) and r.metadata["segy_revision"] == 2
    assert r.data.dtype == np.float32
    np.testing.assert_array_equal(r.data, data)
    p1 = tmp_path / "rev1.sgy"
    _foreign(p1, rev=1, ext=55.0, bin_interval=94)
    assert gpr3d.read(p1).dt_s == pytest.approx(94e-12, rel=1e-9, abs=0) and gpr3d.read(p1).metadata["segy_revision"] == 1
    p0 = tmp_path / "rev2zero.sgy"
    _foreign(p0, rev=2, ext=0.0, bin_interval=94)
    assert gpr3d.read(p0).dt_s == pytest.approx(94e-12, rel=1e-9, abs=0)  # an empty extended field: the 16-bit one
    pn = tmp_path / "ns.sgy"
    _foreign(pn, text="SAMPLE INTERVAL IN NANOSECONDS", bin_interval=2)
    r = gpr3d.read(pn)
    assert r.dt_s == pytest.approx(2e-9, rel=1e-9, abs=0) and r.metadata["dt_unit"] == "ns"
    pb = tmp_path / "both.sgy"
    _foreign(pb, text="NANOSECONDS OR PICOSECONDS", bin_interval=200)
    assert gpr3d.read(pb).dt_s == pytest.approx(200e-12, rel=1e-9, abs=0)  # both named: the GPR default
    pu = tmp_path / "us.sgy"
    _foreign(pu, bin_interval=1)
    assert gpr3d.read(pu, dt_unit="us").dt_s == pytest.approx(1e-6, rel=1e-9, abs=0)  # one microsecond: still allowed
    with pytest.raises(gpr3d.GPR3DError, match=r"us.sgy: sample interval 2e-06 s \(the field read as us\) is no GPR "):
        _foreign(pu, bin_interval=2)
        gpr3d.read(pu, dt_unit="us")
    with pytest.raises(gpr3d.InvalidDataError, match=r"^dt_unit must be auto, ps, ns or us, got 'ms'$"):
        gpr3d.io.segy.read_segy(pu, dt_unit="ms")


def test_the_interval_from_the_trace_headers_and_none_at_all(tmp_path):
    p = tmp_path / "th.sgy"
    _foreign(p, bin_interval=0, trace_interval=250)
    assert gpr3d.read(p).dt_s == pytest.approx(250e-12, rel=1e-9, abs=0)
    _foreign(p, bin_interval=0, trace_interval=0)
    with pytest.raises(gpr3d.GPR3DError, match=r"th.sgy: gives no sample interval \(binary and trace headers hold 0\)$"):
        gpr3d.read(p)


def test_coordinates_and_their_scalars(tmp_path):
    """Scalars as SEG-Y defines them: negative divides, positive multiplies, zero leaves alone; CDP coordinates
    first, the source's where CDP holds 0; the elevation with its own scalar."""
    TF = segyio.TraceField
    heads = {0: {TF.CDP_X: 1500, TF.CDP_Y: 250, TF.SourceGroupScalar: -100, TF.ReceiverGroupElevation: 30,
                 TF.ElevationScalar: 10},
             1: {TF.CDP_X: 0, TF.SourceX: 7, TF.CDP_Y: 0, TF.SourceY: 9, TF.SourceGroupScalar: 10,
                 TF.ReceiverGroupElevation: -4, TF.ElevationScalar: -2},
             2: {TF.CDP_X: 5, TF.CDP_Y: 6, TF.SourceGroupScalar: 0, TF.ReceiverGroupElevation: 8,
                 TF.ElevationScalar: 0}}
    p = tmp_path / "xy.sgy"
    _foreign(p, n=4, heads=heads)
    r = gpr3d.read(p)
    np.testing.assert_allclose(r.positions_xyz[:3], [[15.0, 2.5, 300.0], [70.0, 90.0, -2.0], [5.0, 6.0, 8.0]])
    np.testing.assert_allclose(r.positions_xyz[3], 0.0)
    assert r.t0_s == 0.0 and r.offset_m == 0.0 and r.frequency_hz is None


def test_only_gpr3d_files_are_read_for_time_zero_offset_and_frequency(tmp_path):
    s = gpr3d.Survey(data=np.ones((3, 16), np.float32), dt_s=1e-10, t0_s=2e-10, offset_m=0.25, frequency_hz=4e8)
    write_segy(s, tmp_path / "ours.sgy")
    r = gpr3d.read(tmp_path / "ours.sgy")
    assert (r.t0_s, r.offset_m, r.frequency_hz, r.metadata["written_by_gpr3d"]) == (2e-10, 0.25, 4e8, True)
    p = tmp_path / "theirs.sgy"
    _foreign(p, text="T0 S 5e-10 OFFSET M 0.3 FREQUENCY HZ 1e8 DT S 3e-10")  # the words, not the mark
    r = gpr3d.read(p)
    assert (r.t0_s, r.offset_m, r.frequency_hz) == (0.0, 0.0, None) and r.dt_s == pytest.approx(1e-10, rel=1e-9, abs=0)


def test_what_gpr3d_writes_in_the_headers(tmp_path):
    TF = segyio.TraceField
    pos = np.c_[[0.0, 1.2345, 2.0], [0.5, 0.5, 0.5], [0.01, 0.02, -0.03]]
    s = gpr3d.Survey(data=np.arange(48, dtype=np.float64).reshape(3, 16), dt_s=1e-10, offset_m=0.3456,
                     positions_xyz=pos, metadata={"format": "dzt", "path": "/some/where/LINE01.DZT"})
    write_segy(s, tmp_path / "w.sgy")
    with segyio.open(tmp_path / "w.sgy", ignore_geometry=True) as f:
        assert f.bin[segyio.BinField.SEGYRevision] == 2 and f.bin[segyio.BinField.SEGYRevisionMinor] == 0
        assert f.bin[segyio.BinField.Format] == 5 and f.bin[segyio.BinField.Samples] == 16
        for i in range(3):
            h = f.header[i]
            assert (h[TF.TRACE_SEQUENCE_LINE], h[TF.TRACE_SEQUENCE_FILE], h[TF.FieldRecord], h[TF.TraceNumber]) == \
                (i + 1, i + 1, i + 1, i + 1)
            assert h[TF.offset] == 346 and h[TF.TRACE_SAMPLE_INTERVAL] == 100
            assert (h[TF.CDP_X], h[TF.GroupX], h[TF.SourceX]) == (round(pos[i, 0] * 1000),) * 3
            assert h[TF.ElevationScalar] == -1000 and h[TF.ReceiverGroupElevation] == round(pos[i, 2] * 1000)
        np.testing.assert_allclose(f.samples[:3], [0.0, 0.1, 0.2])  # the "ms" axis holds ns
        text = bytes(f.text[0]).decode("ascii")
        np.testing.assert_array_equal(segyio.tools.collect(f.trace[:]), s.data.astype(np.float32))
    assert text.startswith("C 1 GPR DATA WRITTEN BY GPR3D")
    assert "SOURCE DZT" in text and "LINE01.DZT" in text


def test_writer_limits(tmp_path):
    write_segy(gpr3d.Survey(data=np.zeros((1, 4)), dt_s=1e-12), tmp_path / "a.sgy")  # 1 ps
    write_segy(gpr3d.Survey(data=np.zeros((1, 4)), dt_s=65.535e-9), tmp_path / "b.sgy")  # 65535 ps
    with pytest.raises(gpr3d.InvalidDataError, match=r"^sample interval 6.5536e-08 s does not fit SEG-Y's 16-bit"):
        write_segy(gpr3d.Survey(data=np.zeros((1, 4)), dt_s=65.536e-9), tmp_path / "c.sgy")
    with pytest.raises(gpr3d.InvalidDataError, match=r"^sample interval 4e-13 s does not fit"):
        write_segy(gpr3d.Survey(data=np.zeros((1, 4)), dt_s=0.4e-12), tmp_path / "c.sgy")
    with pytest.raises(gpr3d.InvalidDataError, match=r"^65536 samples per trace exceed SEG-Y's 16-bit sample count$"):
        write_segy(gpr3d.Survey(data=np.zeros((1, 65536), np.float32), dt_s=1e-10), tmp_path / "c.sgy")
    far = np.array([[2147483.648, 0.0, 0.0]])  # 2^31 mm
    with pytest.raises(gpr3d.InvalidDataError, match=r"^positions exceed SEG-Y's coordinate range \(\|x\| < 2147 km "
                                                     r"in mm\)$"):
        write_segy(gpr3d.Survey(data=np.zeros((1, 4)), dt_s=1e-10, positions_xyz=far), tmp_path / "c.sgy")
    write_segy(gpr3d.Survey(data=np.zeros((1, 4)), dt_s=1e-10, positions_xyz=far - [0.001, 0, 0]), tmp_path / "d.sgy")
    assert not (tmp_path / "c.sgy").exists()


def test_is_segy_by_content(tmp_path):
    from gpr3d.io.segy import is_segy

    for endian, fmt in (("big", 5), ("little", 1), ("big", 8), ("little", 3)):
        p = tmp_path / f"{endian}{fmt}.segy"
        _foreign(p, endian=endian, fmt=fmt)
        assert is_segy(p), (endian, fmt)
    p = tmp_path / "big5.segy"
    raw = bytearray(p.read_bytes())
    raw[3224:3226] = (4).to_bytes(2, "big")  # format 4 (fixed point): not one gpr3d reads
    (tmp_path / "fmt4.sgy").write_bytes(bytes(raw))
    assert not is_segy(tmp_path / "fmt4.sgy")
    raw[3224:3226] = (5).to_bytes(2, "big")
    raw[3220:3222] = (0).to_bytes(2, "big")  # no samples per trace
    (tmp_path / "ns0.sgy").write_bytes(bytes(raw))
    assert not is_segy(tmp_path / "ns0.sgy")
    (tmp_path / "short.sgy").write_bytes(p.read_bytes()[:3599])
    assert not is_segy(tmp_path / "short.sgy")
    (tmp_path / "renamed.dat").write_bytes(p.read_bytes())
    assert not is_segy(tmp_path / "renamed.dat")
    (tmp_path / "exact.sgy").write_bytes(p.read_bytes()[:3600])
    assert is_segy(tmp_path / "exact.sgy")  # headers complete: the reader says what is missing


def test_header_details_and_edges(tmp_path):
    """The 65535-sample maximum is writable and readable; no frequency is written as 0 and read as none; the
    source path keeps its last 50 characters; the offset in millimetres; the first trace's interval where the
    binary header has none; a file of headers and no traces is one line."""
    big = gpr3d.Survey(data=np.zeros((1, 65535), np.float32), dt_s=1e-10)
    write_segy(big, tmp_path / "max.sgy")
    assert gpr3d.io.segy.is_segy(tmp_path / "max.sgy") and gpr3d.read(tmp_path / "max.sgy").n_samples == 65535
    path = "/a/" + "d" * 60 + "/0123456789ABCDEFGHIJ0123456789ABCDEFGHIJ012345678X.DZT"
    s = gpr3d.Survey(data=np.ones((2, 8), np.float32), dt_s=1e-10, offset_m=2.0, metadata={"path": path})
    write_segy(s, tmp_path / "o.sgy")
    r = gpr3d.read(tmp_path / "o.sgy")
    assert r.frequency_hz is None and r.offset_m == 2.0
    with segyio.open(tmp_path / "o.sgy", ignore_geometry=True) as f:
        text = bytes(f.text[0]).decode("ascii")
        assert f.header[0][segyio.TraceField.offset] == 2000
    assert path[-50:].upper() in text and path[-51:].upper() not in text and "NONE" not in text
    p = tmp_path / "th.sgy"
    TF = segyio.TraceField
    _foreign(p, bin_interval=0, trace_interval=250, heads={1: {TF.TRACE_SAMPLE_INTERVAL: 300}})
    assert gpr3d.read(p).dt_s == pytest.approx(250e-12, rel=1e-9, abs=0)
    (tmp_path / "empty.sgy").write_bytes(p.read_bytes()[:3600])
    with pytest.raises(gpr3d.GPR3DError, match=r"empty.sgy: not a readable SEG-Y file"):
        gpr3d.read(tmp_path / "empty.sgy")


@pytest.mark.parametrize("fmt, ok", [(1, True), (2, True), (3, True), (5, True), (8, True), (10, True), (11, True),
                                     (12, True), (16, True), (4, False), (6, False), (9, False), (13, False),
                                     (17, False)])
def test_is_segy_knows_the_sample_formats(tmp_path, fmt, ok):
    from gpr3d.io.segy import is_segy

    p = tmp_path / "f.sgy"
    _foreign(p)
    raw = bytearray(p.read_bytes())
    raw[3224:3226] = fmt.to_bytes(2, "big")
    p.write_bytes(bytes(raw))
    assert is_segy(p) is ok


def test_is_segy_takes_one_sample_and_unsigned_counts(tmp_path):
    from gpr3d.io.segy import is_segy

    p = tmp_path / "one.sgy"
    _foreign(p, ns=1)
    assert is_segy(p)
    raw = bytearray(p.read_bytes())
    raw[3220:3222] = (40000).to_bytes(2, "big")  # above 32767: a count, not a negative number
    p.write_bytes(bytes(raw))
    assert is_segy(p)


# ---------------------------------------------------------------- exact intervals, messages and the text header

import struct  # noqa: E402


def test_the_interval_fields_gpr3d_writes(tmp_path):
    """2.5 ps: the 16-bit fields hold round(2.5) = 2 (Python rounds half to even), the rev 2 extended interval the
    exact 2.5; an interval whose picoseconds do not survive a * 1e12 * 1e-12 round trip comes back exact (from the
    text header's DT S, not from the extended field)."""
    s = gpr3d.Survey(data=np.ones((2, 8), np.float32), dt_s=2.5e-12)
    write_segy(s, tmp_path / "a.sgy")
    raw = (tmp_path / "a.sgy").read_bytes()
    assert struct.unpack(">H", raw[3216:3218])[0] == 2
    assert struct.unpack(">d", raw[3280:3288])[0] == 2.5
    dt = 1.6452134544805177e-10
    assert dt * 1e12 * 1e-12 != dt
    write_segy(s.replace(dt_s=dt), tmp_path / "b.sgy")
    assert struct.unpack(">d", (tmp_path / "b.sgy").read_bytes()[3280:3288])[0] == dt * 1e12
    assert gpr3d.read(tmp_path / "b.sgy").dt_s == dt


def test_a_foreign_rev2_file_reads_the_extended_interval(tmp_path):
    p = tmp_path / "f.sgy"
    _foreign(p, rev=2, ext=93.75, bin_interval=94)
    assert gpr3d.read(p).dt_s == pytest.approx(93.75e-12, rel=1e-12, abs=0)  # not the rounded 94 ps
    _foreign(p, rev=2, ext=0.75, bin_interval=1)  # under one picosecond, still positive
    assert gpr3d.read(p).dt_s == pytest.approx(0.75e-12, rel=1e-12, abs=0)
    _foreign(p, rev=3, ext=93.75, bin_interval=94)  # a later revision: still the extended field
    assert gpr3d.read(p).dt_s == pytest.approx(93.75e-12, rel=1e-12, abs=0)


def test_the_source_line_without_format_or_path(tmp_path):
    write_segy(gpr3d.Survey(data=np.ones((2, 8), np.float32), dt_s=1e-10), tmp_path / "n.sgy")
    with segyio.open(tmp_path / "n.sgy", ignore_geometry=True) as f:
        line9 = bytes(f.text[0]).decode("ascii")[80 * 8 : 80 * 9]  # 80-character card images
    assert line9.split() == ["C", "9", "SOURCE"]
    back = gpr3d.read(tmp_path / "n.sgy")
    assert back.metadata == {"format": "segy", "path": str(tmp_path / "n.sgy"), "segy_revision": 2,
                             "dt_unit": "ps", "written_by_gpr3d": True}


def test_messages_of_the_reader(tmp_path):
    p = tmp_path / "x.sgy"
    write_segy(gpr3d.Survey(data=np.ones((2, 8), np.float32), dt_s=1e-10), p)
    raw = bytearray(p.read_bytes())
    raw[3600 + 240 : 3600 + 244] = struct.pack(">f", float("nan"))  # the first sample of the first trace
    p.write_bytes(bytes(raw))
    with pytest.raises(gpr3d.GPR3DError) as e:
        gpr3d.read(p)
    assert str(e.value) == "x.sgy: holds NaN/inf samples"
    _foreign(p, bin_interval=2000, trace_interval=2000)  # 2000 read as nanoseconds: 2 us
    with pytest.raises(gpr3d.GPR3DError) as e:
        gpr3d.read(p, dt_unit="ns")
    assert str(e.value) == ("x.sgy: sample interval 2e-06 s (the field read as ns) is no GPR interval: a seismic file, "
                            "or its interval unit is not the default (gpr3d.read(..., dt_unit=...))")
    (tmp_path / "h.sgy").write_bytes(p.read_bytes()[:3600])  # headers, no traces
    with pytest.raises(gpr3d.GPR3DError) as e:
        gpr3d.read(tmp_path / "h.sgy")
    assert str(e.value) == "h.sgy: not a readable SEG-Y file (trace index out of range)"


def test_is_segy_reads_little_endian_counts_unsigned(tmp_path):
    from gpr3d.io.segy import is_segy

    p = tmp_path / "le.sgy"
    _foreign(p, endian="little")
    raw = bytearray(p.read_bytes())
    raw[3220:3222] = (40000).to_bytes(2, "little")
    raw[3224:3226] = (5).to_bytes(2, "little")
    p.write_bytes(bytes(raw))
    # the big-endian reading of these fields gives no known format: only the little-endian one can pass
    assert struct.unpack(">H", bytes(raw[3224:3226]))[0] not in (1, 2, 3, 5, 8, 10, 11, 12, 16)
    assert is_segy(p)


def test_intervals_no_radar_records_are_refused_where_they_are_read(tmp_path):
    # issue 31: a text header's "DT S 1e-40" once gave a 4e-42 s record that info, show and migrate went on with
    p = tmp_path / "t.sgy"
    _foreign(p, text="GPR DATA WRITTEN BY GPR3D DT S 1e-40")
    with pytest.raises(gpr3d.GPR3DError) as e:
        gpr3d.read(p)
    assert str(e.value) == ("t.sgy: the sample interval from the textual header's DT S is 1e-40 s, which no radar "
                            "records (expected 1e-14..1e-06 s)")
    _foreign(p, rev=2, ext=1e-5, bin_interval=1)  # 1e-5 ps: under a hundredth of a picosecond
    with pytest.raises(gpr3d.GPR3DError, match=r"from the extended sample interval field \(read as ps\) is 1e-17 s"):
        gpr3d.read(p)
    _foreign(p, text="GPR DATA WRITTEN BY GPR3D DT S 2.5e-11")  # the text's interval, when plausible, is the one read
    assert gpr3d.read(p).dt_s == 2.5e-11
