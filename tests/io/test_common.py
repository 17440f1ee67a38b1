"""The helpers the readers share, by hand: files, sidecars, trace counts, header numbers, GPS to metres."""

import math
import warnings

import numpy as np
import pytest

from gpr3d.core.errors import FormatError, GPR3DError, TruncatedRecordingWarning
from gpr3d.io._common import (
    check_file,
    check_finite,
    data_and_header,
    finite_positive,
    gps_positions,
    hdf5_errors,
    local_metres,
    nmea_degrees,
    sidecar,
    warn_fewer_traces,
    whole_traces,
)


def test_check_file(tmp_path):
    with pytest.raises(FormatError, match="^nope.bin: no such file$"):
        check_file(tmp_path / "nope.bin")
    with pytest.raises(FormatError, match=f"^{tmp_path.name}: is a folder, not a file$"):
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


# ---------------------------------------------------------------- the forked walk of HDF5 files

import os  # noqa: E402
import signal  # noqa: E402
import time  # noqa: E402

from gpr3d.io import _common  # noqa: E402

needs_fork = pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this system")


def _h5(path, n=10):
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs["a"] = 1
        f.create_group("g").attrs["b"] = 2
        f["g/d"] = np.arange(n, dtype=np.float64)
    return path


def _crash(*_a, **_k):
    os.kill(os.getpid(), signal.SIGSEGV)


@needs_fork
@pytest.mark.parametrize("where", ["dataset", "root_attrs", "group_attrs"])
def test_the_walk_reads_what_readers_will_read(tmp_path, monkeypatch, where):
    """The child walk reads every attribute and every dataset: a crash in any of those reads, made here on purpose
    (the child inherits the patched h5py), is reported by the parent as one FormatError naming the file."""
    import h5py

    p = _h5(tmp_path / "w.h5")
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    if where == "dataset":
        monkeypatch.setattr(h5py.Dataset, "__getitem__", _crash)
    else:
        real = h5py.AttributeManager.__getitem__
        name = {"root_attrs": "a", "group_attrs": "b"}[where]  # the root's attribute, or the group's

        def crash_on(self, key):
            if key == name:
                _crash()
            return real(self, key)

        monkeypatch.setattr(h5py.AttributeManager, "__getitem__", crash_on)
    with pytest.raises(FormatError) as e:
        _common.check_hdf5_survives(p)
    assert str(e.value) == "w.h5: HDF5 content is corrupt: the HDF5 library crashed reading it (SIGSEGV)"
    assert not _common._HDF5_SURVIVED


@needs_fork
def test_datasets_over_the_limit_are_not_read(tmp_path, monkeypatch):
    import h5py

    p = _h5(tmp_path / "w.h5", n=10)  # 80 bytes
    monkeypatch.setattr(h5py.Dataset, "__getitem__", _crash)
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    _common.check_hdf5_survives(p, max_bytes=79)  # not read: no crash
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    with pytest.raises(FormatError, match="crashed"):
        _common.check_hdf5_survives(p, max_bytes=80)  # exactly the limit: read


def _counting_fork(monkeypatch):
    children = []
    real_fork = os.fork

    def fork():
        pid = real_fork()
        if pid:
            children.append(pid)
        return pid

    monkeypatch.setattr(_common.os, "fork", fork)
    return children


@needs_fork
def test_a_walk_that_does_not_finish_is_one_line_and_its_child_is_ended(tmp_path, monkeypatch):
    """A damaged file can loop libhdf5 for ever (the reader fuzzer found three): refused, not read after all."""
    p = _h5(tmp_path / "w.h5")
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    monkeypatch.setattr(_common, "_walk_hdf5", lambda *_a: time.sleep(30))
    children = _counting_fork(monkeypatch)
    t = time.monotonic()
    with pytest.raises(FormatError, match=r"w.h5: HDF5 content is corrupt: the HDF5 library did not finish reading "
                                          r"its structure within 0 s"):
        _common.check_hdf5_survives(p, timeout_s=0.3)
    # (ended long before the child's 30 s: the bound holds on a loaded machine too)
    assert time.monotonic() - t < 25 and not _common._HDF5_SURVIVED  # not remembered as walked
    # and the child is gone: killed and reaped, no zombie left
    assert len(children) == 1
    with pytest.raises(ChildProcessError):
        os.waitpid(children[0], os.WNOHANG)


@needs_fork
def test_a_wait_cut_short_ends_the_child_too(tmp_path, monkeypatch):
    """An alarm or Ctrl-C while the parent waits: the child is killed, not left walking (it once ran for hours)."""
    import signal

    class Cut(Exception):
        pass

    def cut(*_a):
        raise Cut

    p = _h5(tmp_path / "w.h5")
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    monkeypatch.setattr(_common, "_walk_hdf5", lambda *_a: time.sleep(30))
    children = _counting_fork(monkeypatch)
    old = signal.signal(signal.SIGALRM, cut)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.3)  # (a fork's child has no timer of its parent's)
        with pytest.raises(Cut):
            _common.check_hdf5_survives(p, timeout_s=30)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    assert len(children) == 1
    with pytest.raises(ChildProcessError):
        os.waitpid(children[0], os.WNOHANG)


@needs_fork
def test_the_walk_is_given_time_by_the_data_it_reads(tmp_path, monkeypatch):
    p = _h5(tmp_path / "w.h5")
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    monkeypatch.setattr(_common, "_walk_hdf5", lambda *_a: time.sleep(30))
    monkeypatch.setattr(_common, "HDF5_WALK_BASE_S", 0.5)
    monkeypatch.setattr(_common, "HDF5_WALK_BYTES_PER_S", p.stat().st_size / 1.0)  # the file's bytes: 1 s more
    t = time.monotonic()
    with pytest.raises(FormatError, match="within 2 s"):  # 0.5 + 1.0 s, rounded
        _common.check_hdf5_survives(p)
    assert 1.4 < time.monotonic() - t < 25  # not before its time; long before the child's 30 s


@needs_fork
def test_the_precheck_can_be_switched_off_and_skips_other_files(tmp_path, monkeypatch):
    p = _h5(tmp_path / "w.h5")
    monkeypatch.setattr(_common, "_walk_hdf5", _crash)
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    monkeypatch.setenv("GPR3D_HDF5_PRECHECK", "0")
    _common.check_hdf5_survives(p)  # switched off: no walk, no error
    monkeypatch.setenv("GPR3D_HDF5_PRECHECK", "1")
    with pytest.raises(FormatError):
        _common.check_hdf5_survives(p)
    monkeypatch.delenv("GPR3D_HDF5_PRECHECK")
    with pytest.raises(FormatError):  # on by default
        _common.check_hdf5_survives(p)
    t = tmp_path / "t.h5"
    t.write_bytes(b"not an HDF5 file at all")
    _common.check_hdf5_survives(t)  # no HDF5 signature: not walked
    _common.check_hdf5_survives(tmp_path / "missing.h5")  # not there: left to the reader


@needs_fork
def test_a_surviving_walk_is_remembered_by_path_size_and_time(tmp_path, monkeypatch):
    p = _h5(tmp_path / "w.h5")
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    _common.check_hdf5_survives(p)
    st = p.stat()
    assert _common._HDF5_SURVIVED == {(str(p.resolve()), st.st_size, st.st_mtime_ns): True}
    # the child leaves with status 0 and no output; the parent is still here to say so
    monkeypatch.setattr(_common, "_HDF5_SURVIVED", {})
    monkeypatch.setattr(_common, "_walk_hdf5", lambda *_a: (_ for _ in ()).throw(ValueError("the reader's to say")))
    _common.check_hdf5_survives(p)  # an error in the child is not a crash
    assert len(_common._HDF5_SURVIVED) == 1


def test_the_pair_given_by_an_upper_case_name(tmp_path):
    (tmp_path / "A.DT1").write_bytes(b"x")
    (tmp_path / "A.HD").write_bytes(b"x")
    (tmp_path / "B.dt1").write_bytes(b"x")
    (tmp_path / "B.hd").write_bytes(b"x")
    assert data_and_header(tmp_path / "A.DT1", (".dt1",), ".hd", "v") == (tmp_path / "A.DT1", tmp_path / "A.HD")
    assert data_and_header(tmp_path / "B.hd", (".dt1",), ".hd", "v") == (tmp_path / "B.dt1", tmp_path / "B.hd")
    assert sidecar(tmp_path / "B.hd", ".DT1") == tmp_path / "B.dt1"  # the lower-case candidate
    assert sidecar(tmp_path / "A.DT1", ".hd") == tmp_path / "A.HD"  # the upper-case candidate


def test_small_boundaries():
    assert whole_traces("f.bin", 3, 1) == 3  # one-byte traces are possible
    pos, _ = gps_positions([0, 0.5], [60.0, 60.001], [10.0, 10.0], [0.0, 0.0], np.array([0.0, 0.25, 0.5]))
    assert pos is not None and pos[1, 1] == pytest.approx(pos[2, 1] / 2)  # fixes half a trace apart


def _callers_file(name):
    """A warning's file is this test file (or, under mutmut, the trampoline that stands in one call frame)."""
    return name == __file__ or name.endswith("trampoline.py")


def test_warnings_point_at_the_reader_s_caller():
    def reader():  # stacklevel 3: the warning is reported at the line that called the reader
        whole_traces("f.bin", 320, 100)

    with pytest.warns(TruncatedRecordingWarning) as w:
        reader()
    assert _callers_file(w[0].filename), w[0].filename

    def reader2():
        warn_fewer_traces("f.bin", 9, 4, "X")

    with pytest.warns(TruncatedRecordingWarning) as w:
        reader2()
    assert _callers_file(w[0].filename), w[0].filename


def test_the_walk_itself_reads_every_attribute_and_the_datasets_up_to_the_limit(tmp_path, monkeypatch):
    """_walk_hdf5 run in this process (the parent only sees a child's crash; and a tool that records which tests
    reach a function sees nothing the child does)."""
    import h5py

    p = _h5(tmp_path / "w.h5", n=10)  # root attribute a, group g with attribute b, dataset g/d of 80 bytes
    with h5py.File(p, "a") as f:
        f["small"] = np.arange(3, dtype=np.int16)  # 6 bytes
        f["small"].attrs["c"] = 3
    attrs, reads = [], []
    real_attr, real_get = h5py.AttributeManager.__getitem__, h5py.Dataset.__getitem__

    def attr(self, key):
        attrs.append(key)
        return real_attr(self, key)

    def get(self, key):
        reads.append((self.name, key))
        return real_get(self, key)

    monkeypatch.setattr(h5py.AttributeManager, "__getitem__", attr)
    monkeypatch.setattr(h5py.Dataset, "__getitem__", get)
    _common._walk_hdf5(str(p), 80)
    assert sorted(attrs) == ["a", "b", "c"]
    assert sorted(reads) == [("/g/d", ()), ("/small", ())]  # both whole: 80 bytes is exactly the limit
    attrs.clear(), reads.clear()
    _common._walk_hdf5(str(p), 79)
    assert reads == [("/small", ())] and sorted(attrs) == ["a", "b", "c"]
    reads.clear()
    _common._walk_hdf5(str(p), 5)  # 6 bytes of int16: over
    assert reads == []
    with pytest.raises(OSError):  # no file: the walk itself fails (the child would keep that for the reader)
        _common._walk_hdf5(str(tmp_path / "none.h5"), 80)
