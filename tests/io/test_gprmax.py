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
    gprMax = pytest.importorskip("gprMax")
    merge = pytest.importorskip("gprMax.toolboxes.Utilities.outputfiles_merge")
    d = tmp_path_factory.mktemp("gprmax")
    inp = d / "cyl.in"
    inp.write_text(MODEL)
    gprMax.run(inputfile=str(inp), n=N_TRACES, hide_progress_bars=True, log_level=40)
    merge.merge_files([d / f"cyl{i}.h5" for i in range(1, N_TRACES + 1)], d / "cyl_merged.h5")
    return d


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


def test_missing_component_and_nan(tmp_path):
    import h5py

    p = write_gprmax3_out(tmp_path / "x.out")
    with pytest.raises(FormatError, match="no Iz output"):
        read_gprmax(p, component="Iz")
    with h5py.File(p, "a") as f:
        f["rxs/rx1/Ez"][3, 1] = np.nan
    with pytest.raises(FormatError, match="1 NaN/inf samples"):
        gpr3d.read(p)


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
