"""Format detection and the read entry points: which reader answers, and what a file nobody reads is told."""

import dataclasses
import struct

import numpy as np
import pytest

import gpr3d
from gpr3d import Survey
from gpr3d.core.errors import FormatError, UnknownFormatError
from gpr3d.io import registry
from gpr3d.io.registry import FORMATS, Format, detect_format, read, read_all, register
from tests.io.makers import write_dt1, write_dzt, write_rd3


def test_each_format_is_detected_by_its_reader(tmp_path):
    write_dzt(tmp_path / "a.DZT")
    write_dt1(tmp_path / "b")
    write_rd3(tmp_path / "c")
    Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10).save(tmp_path / "d.h5")
    assert detect_format(tmp_path / "a.DZT") == "dzt"
    assert detect_format(tmp_path / "b.DT1") == "dt1" and detect_format(tmp_path / "b.HD") == "dt1"
    assert detect_format(tmp_path / "c.rd3") == "rd3" and detect_format(tmp_path / "c.rad") == "rd3"
    assert detect_format(tmp_path / "d.h5") == "gpr3d"
    assert list(FORMATS) == ["gpr3d", "gprmax", "dzt", "dt1", "rd3", "segy"]  # content first, then pairs
    assert FORMATS["dzt"].extensions == (".dzt",) and FORMATS["rd3"].extensions == (".rd3", ".rd7", ".rad")


@pytest.mark.parametrize("name, partner, vendor", [
    ("line.DT1", "line.HD", "pulseEKKO"), ("line.hd", "line.DT1", "pulseEKKO"), ("x.rd3", "x.RAD", "MALA"),
    ("x.rd7", "x.RAD", "MALA"), ("x.rad", "x.RD3 or x.RD7", "MALA"),
])
def test_a_missing_partner_file_is_named(tmp_path, name, partner, vendor):
    p = tmp_path / name
    p.write_bytes(b"\x01\x02" * 300)
    with pytest.raises(UnknownFormatError) as e:
        detect_format(p)
    assert str(e.value) == (f"{name}: its partner file {partner} is missing ({vendor} keeps data and header in two "
                            "files with one name): copy it beside this one")


@pytest.mark.parametrize("name, data_file", [("a.DZG", ".DZT"), ("a.dzx", ".DZT"), ("a.cor", ".rd3"),
                                             ("a.GPS", ".DT1")])
def test_a_sidecar_is_pointed_at_its_data_file(tmp_path, name, data_file):
    p = tmp_path / name
    p.write_text("$GPGGA,1\n")
    with pytest.raises(UnknownFormatError, match=f"^{name}: is a sidecar \\(GPS/metadata\\) file: read the "
                                                 f"\\{data_file} data file beside it$"):
        detect_format(p)


def test_an_extension_that_lies_and_one_nobody_reads(tmp_path):
    p = tmp_path / "x.sgy"
    p.write_bytes(b"\0" * 100)
    # one reader owns .sgy: its own reason, not "not a valid file"
    with pytest.raises(UnknownFormatError, match=r"^x.sgy: is not a valid segy file: not a readable SEG-Y file \("):
        detect_format(p)
    p = tmp_path / "x.h5"
    p.write_bytes(b"\0" * 100)
    with pytest.raises(UnknownFormatError, match="not a valid gpr3d/gprmax file"):
        detect_format(p)
    q = tmp_path / "x.txt"
    q.write_text("hello")
    with pytest.raises(UnknownFormatError) as e:
        detect_format(q)
    assert str(e.value) == ("x.txt: unrecognised file format (readers exist for .dt1, .dzt, .h5, .hd, .hdf5, .out, "
                            ".rad, .rd3, .rd7, .segy, .sgy)")


def test_read_all_with_a_format_and_reader_options(tmp_path):
    p = write_dzt(tmp_path / "a.DZT", n_channels=2)
    assert len(read_all(p)) == 2 and len(read_all(p, format="dzt")) == 2
    assert read(p, channel=1).metadata["channel"] == 1
    assert read_all(p, gps=False)[0].metadata["channel"] == 0  # an option of the DZT reader
    with pytest.raises(FormatError, match=r"^a.DZT: has 2 channel\(s\); channel 2 does not exist$"):
        read(p, channel=2)
    with pytest.raises(FormatError, match="channel -1 does not exist"):
        read(p, channel=-1)
    with pytest.raises(FormatError, match=r"^a.DZT: unknown format 'tiff'; known: gpr3d, gprmax, dzt, dt1, rd3, segy$"):
        read_all(p, format="tiff")
    with pytest.raises(FormatError, match=r"^a.DZT: the dzt reader takes no option 'component'$"):
        read_all(p, component="Ez")


def test_a_reader_type_error_that_is_not_about_options_passes_through(tmp_path, monkeypatch):
    p = write_dzt(tmp_path / "a.DZT")

    def broken(path, **kw):
        raise TypeError("a bug in the reader")

    monkeypatch.setitem(FORMATS, "dzt", Format("dzt", "d", (".dzt",), FORMATS["dzt"].is_format, broken))
    with pytest.raises(TypeError, match="a bug in the reader"):
        read_all(p)


def test_register_adds_and_replaces(tmp_path, monkeypatch):
    monkeypatch.setattr(registry, "FORMATS", dict(FORMATS))
    p = tmp_path / "x.zzz"
    p.write_text("ZZZ")
    fmt = Format("zzz", "test", (".zzz",), lambda q: q.read_text() == "ZZZ",
                 lambda q: [Survey(data=np.zeros((1, 2), np.float32), dt_s=1e-10)])
    register(fmt)
    assert registry.detect_format(p) == "zzz" and registry.read(p).dt_s == 1e-10
    register(Format("zzz", "again", (".zzz",), lambda q: False, fmt.read))
    assert registry.FORMATS["zzz"].description == "again" and len(registry.FORMATS) == 7


@pytest.mark.parametrize("where, value, reason", [
    (6, struct.pack("<H", 7), "header gives 7 bits per sample (expected 8, 16 or 32)"),
    (4, struct.pack("<H", 0), "header gives 0 samples per trace"),
    (26, struct.pack("<f", float("nan")), "header field range (ns) = nan is not a positive number"),
    (52, struct.pack("<H", 0), "header gives 0 channels (expected 1..16)"),
])
def test_a_dzt_its_detector_declines_gets_its_reader_s_reason(tmp_path, where, value, reason):
    # issue 31: these were all "not a valid dzt file (corrupt, truncated, or a missing sidecar header)", and a DZT has
    # no sidecar; the reason showed only with --format dzt
    raw = bytearray(write_dzt(tmp_path / "a.DZT", n_traces=4, n_samples=16).read_bytes())
    raw[where : where + len(value)] = value
    p = tmp_path / "bad.DZT"
    p.write_bytes(bytes(raw))
    for call in (detect_format, read_all):
        with pytest.raises(FormatError) as e:
            call(p)
        assert str(e.value).startswith(f"bad.DZT: is not a valid dzt file: {reason}")


def test_paths_that_are_no_files_say_what_they_are(tmp_path):
    import os

    loop = tmp_path / "loop.DZT"
    os.symlink(loop, loop)
    with pytest.raises(FormatError, match=r"^loop.DZT: is a loop of symbolic links, not a file$"):
        read_all(loop)
    dangling = tmp_path / "gone.DZT"
    os.symlink(tmp_path / "nothere.DZT", dangling)
    with pytest.raises(FormatError, match=r"^gone.DZT: is a symbolic link to .*nothere.DZT, which does not exist$"):
        read_all(dangling)
    fifo = tmp_path / "pipe.DZT"
    os.mkfifo(fifo)
    with pytest.raises(FormatError, match=r"^pipe.DZT: is a named pipe \(FIFO\), not a regular file"):
        read_all(fifo)  # (once "file is empty"; opening it would have waited for a writer)
    with pytest.raises(FormatError, match=r"^nofile.DZT: no such file$"):
        read_all(tmp_path / "nofile.DZT")
    with pytest.raises(FormatError, match=r"^a.DZT: no such file$"):
        read_all(tmp_path / "nodir" / "a.DZT")


def test_what_makes_no_survey_is_named_by_its_file_and_memory_is_one_line(tmp_path, monkeypatch):
    from gpr3d.io import registry

    p = write_dzt(tmp_path / "m.DZT", n_traces=4, n_samples=16)

    def survey_error(path, **kw):
        raise gpr3d.InvalidDataError("data holds 3 NaN/inf samples")

    def no_memory(path, **kw):
        raise MemoryError

    fmt = registry.FORMATS["dzt"]
    monkeypatch.setitem(registry.FORMATS, "dzt", dataclasses.replace(fmt, read=survey_error))
    with pytest.raises(FormatError, match=r"^m.DZT: data holds 3 NaN/inf samples$"):
        read_all(p)
    monkeypatch.setitem(registry.FORMATS, "dzt", dataclasses.replace(fmt, read=no_memory))
    with pytest.raises(FormatError, match=rf"^m.DZT: reading it needs more memory than this machine has \(the file "
                                          rf"is {p.stat().st_size:,} bytes; its header may claim far more"):
        read_all(p)


def test_the_owner_of_an_extension_speaks_when_its_detector_declines(tmp_path, monkeypatch):
    """The reader of the one format claiming an extension is asked: its FormatError's problem, another GPR3DError's
    text, or (where the reader takes what its detector declined) that format."""
    p = tmp_path / "odd.sgy"
    p.write_bytes(b"\1" * 4000)
    fmt = FORMATS["segy"]

    def survey_error(path, **kw):
        raise gpr3d.InvalidDataError("dt_s = 1e-20 s is implausible")

    monkeypatch.setitem(FORMATS, "segy", dataclasses.replace(fmt, read=survey_error))
    with pytest.raises(UnknownFormatError) as e:
        detect_format(p)
    assert str(e.value) == "odd.sgy: is not a valid segy file: dt_s = 1e-20 s is implausible"
    monkeypatch.setitem(FORMATS, "segy", dataclasses.replace(fmt, read=lambda path, **kw: []))
    assert detect_format(p) == "segy"
    q = tmp_path / "x.h5"  # two formats claim .h5: neither reader is asked
    q.write_bytes(b"\0" * 100)
    with pytest.raises(UnknownFormatError) as e:
        detect_format(q)
    assert str(e.value) == "x.h5: has a .h5 extension but is not a valid gpr3d/gprmax file (corrupt or truncated)"
