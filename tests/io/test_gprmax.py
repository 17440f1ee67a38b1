"""gprMax outputs, made by running gprMax 4 itself on a tiny 2D model."""

import numpy as np
import pytest

import gpr3d
from gpr3d.core.errors import FormatError
from gpr3d.core.units import C0
from gpr3d.io.gprmax import gprmax_to_world, read_gprmax, read_gprmax_waveform
from tests.io.makers import expected_values, write_gprmax3_out

MODEL = """#title: gpr3d test cylinder
#domain: 0.160 0.100 0.002
#dx_dy_dz: 0.002 0.002 0.002
#time_window: 3e-9
#material: 4 0 1 0 half_space
#waveform: ricker 1 2e9 my_ricker
#hertzian_dipole: z 0.040 0.080 0 my_ricker
#rx: 0.060 0.080 0
#src_steps: 0.010 0 0
#rx_steps: 0.010 0 0
#box: 0 0 0 0.160 0.080 0.002 half_space
#cylinder: 0.080 0.040 0 0.080 0.040 0.002 0.005 pec
"""
N_TRACES = 5


@pytest.fixture(scope="module")
def gprmax_run(tmp_path_factory):
    """gprMax 4 run on MODEL (5 traces) and its merge tool. The outputs are kept in the system's temporary folder,
    keyed by the model and gprMax's version, so that later sessions (and the mutation runs, one session per
    mutant) read what gprMax made instead of running it again."""
    import hashlib
    import importlib.metadata
    import os
    import shutil
    import tempfile
    from pathlib import Path

    gprMax = pytest.importorskip("gprMax")
    merge = pytest.importorskip("gprMax.toolboxes.Utilities.outputfiles_merge")
    key = hashlib.sha256((MODEL + importlib.metadata.version("gprMax")).encode()).hexdigest()[:16]
    cache = Path(tempfile.gettempdir()) / "gpr3d-test-gprmax" / key
    if (cache / "cyl_merged.h5").exists():
        return cache
    d = tmp_path_factory.mktemp("gprmax")
    inp = d / "cyl.in"
    inp.write_text(MODEL)
    gprMax.run(inputfile=str(inp), n=N_TRACES, hide_progress_bars=True, log_level=40)
    merge.merge_files([d / f"cyl{i}.h5" for i in range(1, N_TRACES + 1)], d / "cyl_merged.h5")
    cache.parent.mkdir(parents=True, exist_ok=True)
    part = Path(tempfile.mkdtemp(dir=cache.parent))
    for name in ["cyl_merged.h5", *(f"cyl{i}.h5" for i in range(1, N_TRACES + 1))]:
        shutil.copy(d / name, part / name)
    try:
        os.replace(part, cache)  # whole, in one step (another process may have put it there first)
    except OSError:
        shutil.rmtree(part, ignore_errors=True)
    return cache if (cache / "cyl_merged.h5").exists() else d


def test_merged_bscan(gprmax_run):
    import h5py

    path = gprmax_run / "cyl_merged.h5"
    s = gpr3d.read(path)
    with h5py.File(path) as f:
        ez = f["rxs/rx1/Ez"][()]
        dt = f.attrs["dt"]
    assert s.metadata["format"] == "gprmax"
    assert s.shape == (N_TRACES, ez.shape[0])
    np.testing.assert_array_equal(s.data, ez.T.astype(np.float32))
    assert s.dt_s == dt
    # midpoints of tx (0.04 + 0.01 i) and rx (0.06 + 0.01 i), gprMax y -> world z
    np.testing.assert_allclose(s.positions_xyz[:, 0], 0.05 + 0.01 * np.arange(N_TRACES), atol=1e-9)
    np.testing.assert_allclose(s.positions_xyz[:, 2], 0.08, atol=1e-9)
    assert s.offset_m == pytest.approx(0.02)
    assert s.headings_rad == pytest.approx(np.zeros(N_TRACES))  # tx -> rx along +x


def test_single_trace_and_waveform(gprmax_run):
    s = gpr3d.read(gprmax_run / "cyl1.h5")
    assert s.n_traces == 1
    assert s.frequency_hz == 2e9
    t, w = read_gprmax_waveform(gprmax_run / "cyl1.h5")
    # gprMax's Ricker peaks sqrt(2)/f after the start (CONVENTIONS.md)
    assert t[np.argmax(np.abs(w))] == pytest.approx(np.sqrt(2) / 2e9, abs=2 * s.dt_s)
    ey = read_gprmax(gprmax_run / "cyl1.h5", component="Hx")[0]
    assert ey.metadata["component"] == "Hx"


def test_direct_wave_arrives_at_the_analytic_time(gprmax_run):
    """Direct wave: source peak (sqrt(2)/f) plus the 2 cm tx-rx path, along the air/ground interface.

    On the interface the direct wave travels between the air and ground speeds; the peak of
    |Ez| must fall between those two bounds (a physical check of time and units).
    """
    s = gpr3d.read(gprmax_run / "cyl_merged.h5")
    t_src = np.sqrt(2) / 2e9
    peak = np.argmax(np.abs(s.data[0])) * s.dt_s
    fast, slow = t_src + 0.02 / C0, t_src + 0.02 / (C0 / 2.0)
    assert fast - 0.05e-9 <= peak <= slow + 0.1e-9


def test_gprmax3_out_positions_from_steps(tmp_path):
    p = write_gprmax3_out(tmp_path / "old.out", n_traces=4, iterations=30)
    s = gpr3d.read(p)
    np.testing.assert_array_equal(s.data, expected_values(4, 30, 1, 32)[0].astype(np.float32))
    # tx 0.02 + 0.004 i, rx 0.06 + 0.004 i -> midpoint 0.04 + 0.004 i
    np.testing.assert_allclose(s.positions_xyz[:, 0], 0.04 + 0.004 * np.arange(4))
    assert s.offset_m == pytest.approx(0.04)


def test_source_and_receiver_step_on_their_own(tmp_path):
    """A fixed source and a receiver stepping 3 cells (6 mm) a trace: each trace's midpoint and the median
    offset, by hand (the source's own steps, not the receiver's, move the source)."""
    p = write_gprmax3_out(tmp_path / "wa.out", n_traces=4, iterations=30, rxsteps=(3, 0, 0), srcsteps=(0, 0, 0))
    s = gpr3d.read(p)
    tx = 0.02
    rx = 0.06 + 0.006 * np.arange(4)
    np.testing.assert_allclose(s.positions_xyz[:, 0], (tx + rx) / 2)
    np.testing.assert_allclose(s.positions_xyz[:, 1], 0.0, atol=1e-12)  # gprMax z = 0 -> world y = 0
    np.testing.assert_allclose(s.positions_xyz[:, 2], 0.1)  # gprMax y (up) -> world z
    assert s.offset_m == pytest.approx(np.median(rx - tx))


def test_world_frame_is_right_handed():
    axes = gprmax_to_world(np.eye(3))
    assert np.linalg.det(axes) == pytest.approx(1.0)
    np.testing.assert_allclose(axes[1], [0, 0, 1])  # gprMax y (vertical) -> world z (up)


def test_gprmax3_merge_layout_without_the_gprmax_attribute(tmp_path):
    """gprMax 3's merge tool writes only Iterations, dt, nrx and rxs/rxN/<component>: recognised by that structure,
    read with its samples and time step, and with no positions (not every trace at the origin)."""
    import h5py

    from gpr3d.io.registry import detect_format

    rng = np.random.default_rng(5)
    ez = rng.standard_normal((120, 7))
    hx = rng.standard_normal((120, 7))
    p = tmp_path / "merged.out"
    with h5py.File(p, "w") as f:
        f.attrs["Iterations"] = 120
        f.attrs["dt"] = 4.7e-12
        f.attrs["nrx"] = 1
        f["rxs/rx1/Ez"] = ez
        f["rxs/rx1/Hx"] = hx
    assert detect_format(p) == "gprmax"
    s = gpr3d.read(p)
    np.testing.assert_array_equal(s.data, ez.T.astype(np.float32))
    assert s.dt_s == 4.7e-12 and s.n_traces == 7
    assert s.positions_xyz is None and s.metadata["positions_source"].startswith("none")
    assert s.metadata["gprmax_version"].startswith("unknown")
    np.testing.assert_array_equal(read_gprmax(p, component="Hx")[0].data, hx.T.astype(np.float32))
    # an HDF5 file with the attributes but no receivers' components is not taken for gprMax
    q = tmp_path / "other.h5"
    with h5py.File(q, "w") as f:
        f.attrs["Iterations"] = 120
        f.attrs["dt"] = 4.7e-12
        f["rxs/rx1/notes"] = np.zeros(3)
    with pytest.raises(FormatError, match="gprMax"):
        read_gprmax(q)


# ---------------------------------------------------------------- files made here, field by field

from gpr3d.io.gprmax import is_gprmax  # noqa: E402


def _file(path, *, attrs=None, rxs=None, srcs=None, tm=None):
    """A gprMax-like HDF5 file: root ``attrs``, ``rxs`` {name: {component: array, "@Position": ...}}, ``srcs``
    {name: {"@Position": ..., "excitation": {attrs, "samples": array}}}, ``tm`` {path: array} under
    trace_metadata."""
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs.update(attrs or {})
        for name, comps in (rxs or {}).items():
            g = f.create_group(f"rxs/{name}")
            for k, v in comps.items():
                if k.startswith("@"):
                    g.attrs[k[1:]] = v
                else:
                    g[k] = v
        for name, spec in (srcs or {}).items():
            g = f.create_group(f"srcs/{name}")
            if "@Position" in spec:
                g.attrs["Position"] = spec["@Position"]
            if "excitation" in spec:
                e = g.create_group("excitation")
                e.attrs.update(spec["excitation"].get("attrs", {}))
                if "samples" in spec["excitation"]:
                    e["samples"] = spec["excitation"]["samples"]
        for key, v in (tm or {}).items():
            f[f"trace_metadata/{key}"] = v
    return path


BASE = {"gprMax": "4.0.1", "Iterations": 6, "dt": 2e-12, "Title": "made here"}


def test_receivers_in_number_order_with_metadata(tmp_path):
    rxs = {f"rx{k}": {"Ez": np.full((6, 3), k, float), "@Position": (0.01 * k, 0.2, 0.0)} for k in (10, 2, 1)}
    srcs = {"src1": {"@Position": (0.0, 0.2, 0.0),
                     "excitation": {"attrs": {"WaveformType": b"ricker", "WaveformFrequency": np.float64(1.5e9),
                                              "SourceType": "HertzianDipole"}}}}
    p = _file(tmp_path / "m.h5", attrs={**BASE, "dx_dy_dz": (0.001, 0.002, 0.003), "srcsteps": (2, 0, 0),
                                        "rxsteps": (1, 0, 0)}, rxs=rxs, srcs=srcs)
    surveys = read_gprmax(p)
    assert [s.metadata["receiver"] for s in surveys] == ["rx1", "rx2", "rx10"]
    assert [float(s.data[0, 0]) for s in surveys] == [1.0, 2.0, 10.0]
    s = surveys[1]
    m = s.metadata
    assert (m["format"], m["channel"], m["n_channels"], m["component"]) == ("gprmax", 1, 3, "Ez")
    assert (m["gprmax_version"], m["title"], m["merged"]) == ("4.0.1", "made here", True)
    assert m["dx_dy_dz"] == [0.001, 0.002, 0.003]
    assert m["waveform"] == {"WaveformType": "ricker", "WaveformFrequency": 1.5e9, "SourceType": "HertzianDipole"}
    assert m["antenna"] == "gprMax HertzianDipole" and s.frequency_hz == 1.5e9
    assert m["positions_source"] == "gprMax receiver position + rxsteps"
    # rx2 at x = 0.02 + 0.001 i, the source at 0 + 0.002 i (its own steps times the cell size)
    np.testing.assert_allclose(m["tx_positions_gprmax"], [[0.0, 0.2, 0.0], [0.002, 0.2, 0.0], [0.004, 0.2, 0.0]])
    np.testing.assert_allclose(s.positions_xyz[:, 0], (0.02 + 0.001 * np.arange(3) + 0.002 * np.arange(3)) / 2)
    np.testing.assert_allclose(s.positions_xyz[:, 2], 0.2)
    assert s.offset_m == pytest.approx(np.median(0.02 - 0.001 * np.arange(3)))
    assert s.dt_s == 2e-12


def test_a_single_trace_file_is_not_merged_and_a_source_without_waveform(tmp_path):
    p = _file(tmp_path / "one.h5", attrs=BASE, rxs={"rx1": {"Ez": np.arange(6.0), "@Position": (0.05, 0.1, 0.0)}},
              srcs={"src1": {"@Position": (0.03, 0.1, 0.0)}})
    s = read_gprmax(p)[0]
    assert s.shape == (1, 6) and not s.metadata["merged"]
    assert s.metadata["waveform"] is None and s.metadata["antenna"] == "gprMax" and s.frequency_hz is None
    np.testing.assert_array_equal(s.data[0], np.arange(6.0, dtype=np.float32))
    np.testing.assert_allclose(s.positions_xyz, [[0.04, 0.0, 0.1]])
    # tx at 0.03, rx at 0.05: 2 cm apart, the antenna heading along tx -> rx, world +x
    assert s.offset_m == pytest.approx(0.02) and s.headings_rad[0] == pytest.approx(0.0)


def test_trace_metadata_positions_win_and_must_match(tmp_path):
    tx = np.c_[np.linspace(0, 0.04, 3), np.full(3, 0.1), np.zeros(3)]
    rx = tx + [0.0, 0.0, 0.02]  # receiver 2 cm along gprMax z: world -y
    p = _file(tmp_path / "tm.h5", attrs={**BASE, "rxsteps": (5, 0, 0)},
              rxs={"rx1": {"Ez": np.ones((6, 3)), "@Position": (9.0, 9.0, 9.0)}},
              srcs={"src1": {"@Position": (9.0, 9.0, 9.0)}},
              tm={"rxs/rx1/Position": rx, "srcs/src1/Position": tx})
    s = read_gprmax(p)[0]
    assert s.metadata["positions_source"] == "gprMax trace_metadata"
    np.testing.assert_allclose(s.positions_xyz, np.c_[tx[:, 0], np.full(3, -0.01), np.full(3, 0.1)])
    np.testing.assert_allclose(s.headings_rad, -np.pi / 2)  # tx -> rx points to world -y
    bad = _file(tmp_path / "tm2.h5", attrs=BASE, rxs={"rx1": {"Ez": np.ones((6, 3))}},
                srcs={"src1": {"@Position": (0.0, 0.1, 0.0)}}, tm={"rxs/rx1/Position": rx[:2]})
    with pytest.raises(FormatError, match="^tm2.h5: trace_metadata positions do not match the number of traces$"):
        read_gprmax(bad)


def test_a_receiver_without_position_or_steps_has_no_positions(tmp_path):
    p = _file(tmp_path / "n.h5", attrs=BASE, rxs={"rx1": {"Ez": np.ones((6, 2))}})
    s = read_gprmax(p)[0]
    assert s.positions_xyz is None and s.orientations_quat_wxyz is None and s.offset_m == 0.0
    assert s.metadata["positions_source"] == "none in the file (give the trace positions)"
    assert s.metadata["tx_positions_gprmax"] is None
    # a receiver with steps but no source: the source is taken at the receiver (zero offset, no heading)
    p = _file(tmp_path / "r.h5", attrs={**BASE, "rxsteps": (1, 0, 0), "dx_dy_dz": (0.01, 0.01, 0.01)},
              rxs={"rx1": {"Ez": np.ones((6, 2))}})
    s = read_gprmax(p)[0]
    np.testing.assert_allclose(s.positions_xyz, [[0, 0, 0], [0.01, 0, 0]])
    assert s.offset_m == 0.0 and s.orientations_quat_wxyz is None


@pytest.mark.parametrize("attrs, rxs, message", [
    ({"Iterations": 6, "dt": 1e-12}, {}, "HDF5 file has neither a 'gprMax' attribute nor gprMax's layout"),
    ({"gprMax": "4", "Iterations": 6}, {"rx1": {"Ez": np.ones(6)}}, "gprMax output lacks the 'dt' or 'Iterations'"),
    ({"gprMax": "4", "dt": 1e-12}, {"rx1": {"Ez": np.ones(6)}}, "gprMax output lacks the 'dt' or 'Iterations'"),
    ({"gprMax": "4", "Iterations": 6, "dt": 0.0}, {"rx1": {"Ez": np.ones(6)}}, "gprMax dt = 0.0 is not a positive"),
    ({"gprMax": "4", "Iterations": 6, "dt": float("nan")}, {"rx1": {"Ez": np.ones(6)}}, "gprMax dt = nan"),
    ({"gprMax": "4", "Iterations": 6, "dt": 1e-12}, {}, "gprMax output holds no receivers"),
    # issue 31's fuzzing: once int(inf), an OverflowError
    ({"gprMax": "4", "Iterations": float("inf"), "dt": 1e-12}, {"rx1": {"Ez": np.ones(6)}},
     "header field Iterations = inf is not a whole number"),
    ({"gprMax": "4", "Iterations": 6.5, "dt": 1e-12}, {"rx1": {"Ez": np.ones(6)}},
     "header field Iterations = 6.5 is not a whole number"),
    ({"gprMax": "4", "Iterations": 1, "dt": 1e-12}, {"rx1": {"Ez": np.ones(1)}},
     "header field Iterations = 1 is implausible (expected 2..1000000000)"),
    ({"gprMax": "4", "Iterations": np.ones((2, 2)), "dt": 1e-12}, {"rx1": {"Ez": np.ones(6)}},
     "header field Iterations = array([[1., 1.], [1., 1.]]) is not a number"),
    ({"gprMax": "4", "Iterations": 7, "dt": 1e-12}, {"rx1": {"Ez": np.ones((6, 2))}},
     "rx1/Ez has shape (6, 2), expected (7, n_traces)"),
    ({"gprMax": "4", "Iterations": 6, "dt": 1e-12}, {"rx1": {"Ez": np.ones((6, 2, 2))}}, "rx1/Ez has shape (6, 2, 2)"),
    ({"gprMax": "4", "Iterations": 6, "dt": 1e-12}, {"rx1": {"Hx": np.ones(6), "Other": np.ones(6)}},
     "receiver rx1 has no Ez output (has Hx)"),
    ({"gprMax": "4", "Iterations": 6, "dt": 1e-12}, {"rx1": {"Other": np.ones(6)}},
     "receiver rx1 has no Ez output (has none)"),
])
def test_broken_outputs_are_named(tmp_path, attrs, rxs, message):
    p = _file(tmp_path / "b.h5", attrs=attrs, rxs=rxs)
    with pytest.raises(FormatError) as e:
        read_gprmax(p)
    assert str(e.value).startswith(f"b.h5: {message}")


def test_not_hdf5_and_unknown_components(tmp_path):
    t = tmp_path / "t.out"
    t.write_text("not hdf5 at all")
    with pytest.raises(FormatError, match="^t.out: not an HDF5 file, so not a gprMax output$"):
        read_gprmax(t)
    assert not is_gprmax(t)
    p = write_gprmax3_out(tmp_path / "x.out")
    with pytest.raises(FormatError, match="unknown field component 'Ew'; choose from Ex, Ey, Ez, Hx, Hy, Hz, Ix"):
        read_gprmax(p, component="Ew")
    np.testing.assert_array_equal(read_gprmax(p, component="Hx")[0].data,
                                  0.5 * expected_values(4, 30, 1, 32)[0].astype(np.float32))


def test_is_gprmax(tmp_path):
    assert is_gprmax(write_gprmax3_out(tmp_path / "x.out"))
    assert is_gprmax(_file(tmp_path / "v.h5", attrs={"gprMax": "4"}, rxs={"rx1": {"Ez": np.ones(3)}}))
    assert not is_gprmax(_file(tmp_path / "a.h5", attrs={"gprMax": "4"}))  # no receivers
    assert is_gprmax(_file(tmp_path / "l.h5", attrs={"Iterations": 3, "dt": 1e-12}, rxs={"rx1": {"Hz": np.ones(3)}}))
    assert not is_gprmax(_file(tmp_path / "o.h5", attrs={"Iterations": 3, "dt": 1e-12},
                               rxs={"rx1": {"Foo": np.ones(3)}}))  # no field component
    assert not is_gprmax(_file(tmp_path / "d.h5", attrs={"Iterations": 3}, rxs={"rx1": {"Ez": np.ones(3)}}))
    assert not is_gprmax(tmp_path / "missing.h5")


def test_the_waveform_reader(tmp_path):
    p = _file(tmp_path / "w.h5", attrs=BASE, rxs={"rx1": {"Ez": np.ones(6)}},
              srcs={"src1": {"excitation": {"attrs": {"SampleInterval": 1e-12, "TimeSampleOffset": 5e-13},
                                            "samples": np.array([0.0, 1.0, -1.0])}},
                    "src2": {"excitation": {"samples": np.array([2.0, 3.0])}}})
    t, w = read_gprmax_waveform(p)
    np.testing.assert_allclose(t, [5e-13, 1.5e-12, 2.5e-12])
    np.testing.assert_array_equal(w, [0.0, 1.0, -1.0])
    t, w = read_gprmax_waveform(p, source="src2")  # no interval of its own: the file's dt, no offset
    np.testing.assert_allclose(t, [0.0, 2e-12])
    assert read_gprmax_waveform(p, source="src3") is None


def test_metadata_fields_and_their_defaults(tmp_path):
    ex = {"attrs": {"WaveformType": np.bytes_(b"gaussian"), "WaveformFrequency": np.float64(9e8),
                    "WaveformAmplitude": np.float64(2.0)}}  # no SourceType
    p = _file(tmp_path / "m.h5", attrs={"gprMax": np.bytes_(b"4.0.1"), "Iterations": 6, "dt": 1e-12},
              rxs={"rx1": {"Ez": np.ones((6, 2)), "@Position": (0.1, 0.2, 0.0)}},
              srcs={"src1": {"@Position": (0.0, 0.2, 0.0), "excitation": ex}})
    s = read_gprmax(p)[0]
    m = s.metadata
    assert m["gprmax_version"] == "4.0.1" and m["title"] == "" and m["path"] == str(p)
    assert m["waveform"] == {"WaveformType": "gaussian", "WaveformFrequency": 9e8, "WaveformAmplitude": 2.0}
    assert type(m["waveform"]["WaveformFrequency"]) is float and type(m["waveform"]["WaveformType"]) is str
    assert m["antenna"] == "gprMax source" and m["merged"]  # two traces: merged
    assert m["tx_positions_gprmax"] == [[0.0, 0.2, 0.0], [0.0, 0.2, 0.0]]


def test_merged_by_attribute_and_the_tx_list_limit(tmp_path):
    one = _file(tmp_path / "one.h5", attrs={**BASE, "ntraces": 1}, rxs={"rx1": {"Ez": np.ones(6)}})
    assert read_gprmax(one)[0].metadata["merged"]  # one trace, but the merge tool's attribute
    for n, listed in ((4096, True), (4097, False)):
        p = _file(tmp_path / f"n{n}.h5", attrs={**BASE, "rxsteps": (1, 0, 0)},
                  rxs={"rx1": {"Ez": np.zeros((6, n)), "@Position": (0.0, 0.1, 0.0)}},
                  srcs={"src1": {"@Position": (0.0, 0.1, 0.0)}})
        assert (read_gprmax(p)[0].metadata["tx_positions_gprmax"] is not None) == listed


def test_steps_without_a_cell_size_and_a_source_without_position(tmp_path):
    # no dx_dy_dz: the steps count in metres (a cell of 1); a source group without Position: the receiver's place
    p = _file(tmp_path / "s.h5", attrs={**BASE, "rxsteps": (2, 0, 0)},
              rxs={"rx1": {"Ez": np.ones((6, 2)), "@Position": (0.5, 0.1, 0.0)}}, srcs={"src1": {}})
    s = read_gprmax(p)[0]
    np.testing.assert_allclose(s.positions_xyz[:, 0], [0.5, 2.5])
    assert s.offset_m == 0.0
    q = _file(tmp_path / "t.h5", attrs={**BASE, "rxsteps": (0, 1, 1)},  # steps up and along gprMax z, cells of 1 m
              rxs={"rx1": {"Ez": np.ones((6, 2)), "@Position": (0.5, 0.1, 0.0)}})
    np.testing.assert_allclose(read_gprmax(q)[0].positions_xyz, [[0.5, 0.0, 0.1], [0.5, -1.0, 1.1]])


def test_receivers_without_a_number_come_first_and_components_are_listed(tmp_path):
    p = _file(tmp_path / "r.h5", attrs=BASE, rxs={"rx1": {"Ez": np.full(6, 1.0)}, "rxa": {"Ez": np.full(6, 2.0)}})
    assert [s.metadata["receiver"] for s in read_gprmax(p)] == ["rxa", "rx1"]
    q = _file(tmp_path / "c.h5", attrs=BASE, rxs={"rx1": {"Hx": np.ones(6), "Hy": np.ones(6)}})
    with pytest.raises(FormatError) as e:
        read_gprmax(q)
    assert str(e.value) == "c.h5: receiver rx1 has no Ez output (has Hx, Hy)"


def test_messages_name_the_file(tmp_path):
    p = write_gprmax3_out(tmp_path / "x.out")
    with pytest.raises(FormatError, match="^x.out: unknown field component 'Ew'"):
        read_gprmax(p, component="Ew")
    with pytest.raises(FormatError, match=r"^x.out: receiver rx1 has no Iz output \(has Ex, Ey, Ez, Hx, Hy, Hz\)$"):
        read_gprmax(p, component="Iz")
    import h5py

    with h5py.File(p, "a") as f:
        f["rxs/rx1/Ez"][0, 0] = np.inf
    with pytest.raises(FormatError, match=r"^x.out: rx1/Ez holds 1 NaN/inf samples \(the simulation went unstable\?\)$"):
        read_gprmax(p)
    bad = tmp_path / "bad.out"
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x01" * 200)
    with pytest.raises(FormatError, match="^bad.out: HDF5 content is corrupt or truncated"):
        read_gprmax(bad)
    assert not is_gprmax(bad)
    n = _file(tmp_path / "n.h5", attrs={"Iterations": 6, "dt": 1e-12})
    with pytest.raises(FormatError) as e:
        read_gprmax(n)
    assert str(e.value) == ("n.h5: HDF5 file has neither a 'gprMax' attribute nor gprMax's layout (Iterations, dt and "
                            "rxs/rxN/<component>): not a gprMax output")
    lay = _file(tmp_path / "l.h5", attrs={"Iterations": 6, "dt": 1e-12}, rxs={"rx1": {"Ez": np.ones(6)}})
    assert read_gprmax(lay)[0].metadata["gprmax_version"] == "unknown (merged file without a gprMax attribute)"


def test_gprmax_to_world_on_any_leading_shape():
    p = np.arange(12.0).reshape(2, 2, 3)
    w = gprmax_to_world(p)
    assert w.shape == (2, 2, 3)
    np.testing.assert_array_equal(w[1, 0], [6.0, -8.0, 7.0])
    z = gprmax_to_world([[-0.0, 0.0, 0.0]])
    assert not np.any(np.signbit(z))  # no negative zeros in the output
