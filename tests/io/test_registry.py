"""Format detection and the read entry points: which reader answers, and what a file nobody reads is told."""

import numpy as np
import pytest

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
    with pytest.raises(UnknownFormatError, match="^x.sgy: has a .sgy extension but is not a valid segy file "
                                                 r"\(corrupt, truncated, or a missing sidecar header\)$"):
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
