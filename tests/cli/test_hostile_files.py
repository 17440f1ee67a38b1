"""Issue 31's hostile files through the command line: each one line on stderr, exit 1, no traceback.

The cases were found by trying the commands as a user would; each was a traceback, a misleading message or a
silently wrong result before. The readers' own tests check the messages word for word; this checks that what
reaches a user is one line naming the file and the problem, and that ``info`` on several files still reports
the good ones.
"""

import json
import struct
from pathlib import Path

import h5py
import numpy as np
import pytest

import gpr3d
from gpr3d.cli.main import main
from tests.io.makers import write_dt1, write_dzt, write_rd3
from tests.io.test_gprmax import BASE, _file

DZT = Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT"


def _header_edited(data, header_suffix, old, new):
    """A made data/header pair whose text header has ``old`` replaced by ``new``; the data file's path."""
    header = data.with_suffix(header_suffix)
    assert old in header.read_text()
    header.write_text(header.read_text().replace(old, new))
    return data


def _hd(tmp_path, old, new):
    return _header_edited(write_dt1(tmp_path / "line"), ".HD", old, new)


def _rad(tmp_path, old, new):
    return _header_edited(write_rd3(tmp_path / "ten"), ".rad", old, new)


def _dzt_field(tmp_path, at, value):
    raw = bytearray(DZT.read_bytes())
    raw[at : at + len(value)] = value
    p = tmp_path / "bad.DZT"
    p.write_bytes(bytes(raw))
    return p


def _h5(tmp_path, edit):
    p = tmp_path / "s.h5"
    gpr3d.Survey(data=np.ones((4, 8), np.float32), dt_s=1e-10).save(p)
    with h5py.File(p, "r+") as f:
        edit(f["surveys"]["0"])
    return p


def _huge(g):
    del g["data"]
    g.create_dataset("data", shape=(10**6, 10**5), dtype="f4", chunks=(1000, 1000))


CASES = {
    "hd points nan": (lambda t: _hd(t, "NUMBER OF PTS/TRC  = 50", "NUMBER OF PTS/TRC  = nan"),
                      "line.HD: header field NUMBER OF PTS/TRC = nan is not a whole number"),
    "hd traces inf": (lambda t: _hd(t, "NUMBER OF TRACES   = 6", "NUMBER OF TRACES   = inf"),
                      "line.HD: header field NUMBER OF TRACES = inf is not a whole number"),
    "hd window 1e-30 ns": (lambda t: _hd(t, "TOTAL TIME WINDOW  = 100.0", "TOTAL TIME WINDOW  = 1e-30"),
                           "line.HD: the sample interval from TOTAL TIME WINDOW / NUMBER OF PTS/TRC is 2e-41 s"),
    "rad samples nan": (lambda t: _rad(t, "SAMPLES:40", "SAMPLES:nan"),
                        "ten.rad: header field SAMPLES = nan is not a whole number"),
    "rad last trace inf": (lambda t: _rad(t, "LAST TRACE:5", "LAST TRACE:inf"),
                           "ten.rad: header field LAST TRACE = inf is not a whole number"),
    "rad samples disagree": (lambda t: _rad(t, "SAMPLES:40", "SAMPLES:36"),
                             "ten.rad: SAMPLES = 36 does not fit ten.rd3 (400 bytes: no whole number of 36-sample "
                             "traces, but 5 traces (LAST TRACE) of 40 samples): the header or the data is wrong"),
    "dzt 16 channels": (lambda t: _dzt_field(t, 52, struct.pack("<H", 16)),
                        "bad.DZT: is not a valid dzt file: header gives 16 channels, but bytes 1024..2047 hold no "
                        "header of channel 2"),
    "dzt 7 bits": (lambda t: _dzt_field(t, 6, struct.pack("<H", 7)),
                   "bad.DZT: is not a valid dzt file: header gives 7 bits per sample"),
    "dzt nan range": (lambda t: _dzt_field(t, 26, struct.pack("<f", float("nan"))),
                      "bad.DZT: is not a valid dzt file: header field range (ns) = nan is not a positive number"),
    "h5 history an object": (lambda t: _h5(t, lambda g: g.attrs.__setitem__("history_json", json.dumps({"a": 1}))),
                             "s.h5: survey 0: its history_json holds an object, not a list"),
    "h5 no dt_s": (lambda t: _h5(t, lambda g: g.attrs.__delitem__("dt_s")),
                   "s.h5: survey 0 has no dt_s attribute (the sample interval, in seconds)"),
    "h5 declares 373 GiB": (lambda t: _h5(t, _huge),
                            "s.h5: survey 0 declares a 1000000x100000 data set (373 GiB) in a "),
}


@pytest.mark.parametrize("name", list(CASES))
def test_a_hostile_file_is_one_line(tmp_path, capsys, name):
    make, message = CASES[name]
    path = make(tmp_path)
    rc = main(["info", str(path)])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"gpr3d: error: {message}"), err


def test_show_and_process_give_the_same_line(tmp_path, capsys):
    path = CASES["hd points nan"][0](tmp_path)
    for argv in (["show", str(path), "--out", str(tmp_path / "s.png")],
                 ["process", str(path), "--steps", "dewow", "--out", str(tmp_path / "p.h5")]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err == f"gpr3d: error: {CASES['hd points nan'][1]}\n", err
    assert not (tmp_path / "s.png").exists() and not (tmp_path / "p.h5").exists()


def test_info_on_several_files_reports_the_good_ones_beside_a_bad_one(tmp_path, capsys):
    bad = CASES["rad samples nan"][0](tmp_path)
    good = write_dzt(tmp_path / "good.DZT")
    rc = main(["info", str(bad), str(good)])
    out, err = capsys.readouterr()
    assert rc == 1
    assert err == f"gpr3d: error: {CASES['rad samples nan'][1]}\n"
    assert "good.DZT: dzt" in out and "traces x samples : 7 x 64" in out


def test_a_gprmax_merge_without_geometry_says_so(tmp_path, capsys):
    # once a TypeError: the path length of positions that are not there
    p = _file(tmp_path / "merged.h5", attrs=BASE, rxs={"rx1": {"Ez": np.ones((6, 2))}})
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "positions        : none in the file (give the trace positions)" in out and "path length" not in out
