"""reconstruct(): one straight profile falls back to a 2D migration of the plane under it, with targets mapped
back to the world (checked against the forward model's pipes)."""

import json

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import GeometryWarning, InvalidDataError
from gpr3d.core.poses import quat_from_yaw
from gpr3d.migration.reconstruct import (
    ProfileFrame,
    ReconstructConfig,
    reconstruct,
    write_reconstruction,
)
from gpr3d.migration.targets import extract_profile_targets
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model

EPS = 6.0
START = np.array([0.2, 0.1])
DIRECTION = np.array([0.6, 0.8])  # the profile runs north-east, not along a grid axis


def _profile(pipes, n=201, length=2.0):
    along = np.linspace(0.0, length, n)
    xy = START + along[:, None] * DIRECTION
    pos = np.c_[xy, np.zeros(n)]
    quat = quat_from_yaw(np.full(n, np.arctan2(DIRECTION[1], DIRECTION[0])))
    data = forward_model(ForwardScene(eps_r=EPS, pipes=pipes), pos, quat, offset_m=0.05, frequency_hz=800e6,
                         n_samples=256, time_window_s=16e-9, air_wave=1.0, ground_wave=0.5)
    return Survey(data=data, dt_s=16e-9 / 256, offset_m=0.05, frequency_hz=800e6, eps_r=EPS, positions_xyz=pos,
                  orientations_quat_wxyz=quat)


def _crossing(along, top, r=0.02):
    """A pipe crossing the profile at right angles, its top ``top`` deep, ``along`` metres from the start."""
    c = START + along * DIRECTION
    n = np.array([-DIRECTION[1], DIRECTION[0]])
    a, b = c - 1.0 * n, c + 1.0 * n
    return Pipe((a[0], a[1], -top - r), (b[0], b[1], -top - r), r)


def test_profile_frame_maps_both_ways():
    pos = np.c_[START + np.linspace(0, 2, 5)[:, None] * DIRECTION, np.zeros(5)]
    f = ProfileFrame.fit(pos)
    assert f.direction_xy == pytest.approx(tuple(DIRECTION))
    assert f.origin_xy == pytest.approx(tuple(START))
    line = f.to_line(pos)
    np.testing.assert_allclose(line[:, 0], np.linspace(0, 2, 5), atol=1e-12)
    np.testing.assert_allclose(line[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(f.to_world(line[:, 0], line[:, 1]), pos[:, :2], atol=1e-12)
    # a point to the left of the line
    left = np.array([[*(START + 0.5 * DIRECTION + 0.3 * np.array([-0.8, 0.6])), -1.0]])
    np.testing.assert_allclose(f.to_line(left), [[0.5, 0.3, -1.0]], atol=1e-12)


def test_one_straight_profile_falls_back_to_2d(tmp_path):
    s = _profile([_crossing(0.6, 0.3), _crossing(1.4, 0.5)])
    with pytest.warns(GeometryWarning, match="migrated in 2D"):
        rec = reconstruct(s, ReconstructConfig(spacing_m=0.01, max_depth_m=0.7))
    assert rec.frame is not None and rec.grid.ny == 1
    pts = [t for t in rec.targets if t.kind == "point"]
    assert len(rec.targets) == 2 and len(pts) == 2, [(t.kind, t.points_xyz) for t in rec.targets]
    got = sorted(pts, key=lambda t: t.extra["along_m"][0])
    for t, (along, top) in zip(got, ((0.6, 0.3), (1.4, 0.5))):
        want_xy = START + along * DIRECTION
        assert t.points_xyz[0][:2] == pytest.approx(tuple(want_xy), abs=0.02)
        assert t.depth_m == pytest.approx(top, abs=0.02)
    files = write_reconstruction(rec, tmp_path, source="line")
    # the data only: the figures are drawn above the migration (gpr3d.pipeline.reconstruction.write_result)
    assert files == ["config.json", "targets.json", "volume.h5", "volume.vti"]
    names = [t["name"] for t in json.loads((tmp_path / "targets.json").read_text())["targets"]]
    assert names == ["T1", "T2"]
    frame = json.loads((tmp_path / "config.json").read_text())["frame"]
    assert frame["kind"] == "profile" and frame["direction_xy"] == pytest.approx(list(DIRECTION))


def test_profile_targets_from_a_known_image():
    """extract_profile_targets on an analytic envelope: a flat bar (a line), a compact blob off the cell centres (a
    point, found to sub-cell accuracy) and a faint smear below the threshold (nothing)."""
    along = np.arange(0, 3.0, 0.01)
    depth = np.arange(0.02, 1.0, 0.01)
    A, D = np.meshgrid(along, depth, indexing="ij")
    bar = np.exp(-0.5 * ((D - 0.5) / 0.02) ** 2) * ((A > 1.0) & (A < 2.0))
    blob = np.exp(-0.5 * (((A - 0.5034) / 0.03) ** 2 + ((D - 0.2976) / 0.02) ** 2))
    faint = 0.1 * np.exp(-0.5 * ((D - 0.8) / 0.02) ** 2)
    targets = extract_profile_targets(bar + blob + faint, along, depth, threshold=0.3, min_line_m=0.3)
    assert sorted(t.kind for t in targets) == ["line", "point"]
    line = next(t for t in targets if t.kind == "line")
    (a0, _, d0), (a1, _, d1) = line.points_xyz
    assert (a0, a1) == (pytest.approx(1.01, abs=0.03), pytest.approx(1.99, abs=0.03))
    assert d0 == pytest.approx(0.5, abs=0.005) and d1 == pytest.approx(0.5, abs=0.005)
    point = next(t for t in targets if t.kind == "point")
    assert point.points_xyz[0][0] == pytest.approx(0.5034, abs=0.002)
    assert point.depth_m == pytest.approx(0.2976, abs=0.002)
    # nothing shallower than min_depth_m
    deep = extract_profile_targets(bar + blob, along, depth, threshold=0.3, min_depth_m=0.4)
    assert [t.kind for t in deep] == ["line"]


def test_traces_all_in_one_place_are_refused():
    s = _profile([_crossing(0.6, 0.3)], n=20, length=0.01)
    with pytest.raises(InvalidDataError, match="no profile and no area"):
        reconstruct(s, ReconstructConfig(spacing_m=0.02, max_depth_m=0.5))


@pytest.fixture(scope="module")
def grid_lines():
    """Seven 1.6 m lines along x, 0.2 m apart, over a pipe along y at x = 0.8 m, its top 0.3 m deep (forward
    model), put together as a grid survey."""
    from gpr3d.core.gridsurvey import assemble_grid

    n = 161
    along = np.linspace(0.0, 1.6, n)
    pipe = Pipe((0.8, -0.3, -0.32), (0.8, 1.5, -0.32), 0.02)
    lines = []
    for k in range(7):
        pos = np.c_[along, np.full(n, 0.2 * k), np.zeros(n)]
        data = forward_model(ForwardScene(eps_r=EPS, pipes=[pipe]), pos, quat_from_yaw(np.zeros(n)), offset_m=0.05,
                             frequency_hz=800e6, n_samples=256, time_window_s=16e-9, air_wave=1.0, ground_wave=0.5)
        lines.append(Survey(data=data, dt_s=16e-9 / 256, offset_m=0.05, frequency_hz=800e6, eps_r=EPS,
                            positions_xyz=np.c_[along, np.zeros(n), np.zeros(n)], metadata={"path": f"L{k}"}))
    return assemble_grid(lines, line_spacing_m=0.2)


@pytest.mark.parametrize("method", ["pseudo3d", "backprojection"])
def test_pseudo3d_and_3d_find_the_pipe_across_the_lines(grid_lines, method):
    rec = reconstruct(grid_lines, ReconstructConfig(spacing_m=0.02, max_depth_m=0.6, method=method))
    lines = [t for t in rec.targets if t.kind == "line"]
    assert lines, [(t.kind, t.points_xyz) for t in rec.targets]
    best = max(lines, key=lambda t: t.length_m)
    p = np.array(best.points_xyz)
    assert np.all(np.abs(p[:, 0] - 0.8) < 0.03) and abs(best.direction[1]) > 0.99
    assert best.depth_m == pytest.approx(0.3, abs=0.03) and best.length_m > 0.8
    assert (rec.fold is None) == (method == "pseudo3d")


def test_pseudo3d_refuses_what_it_cannot_do(grid_lines):
    from gpr3d.migration.reconstruct import check_config

    with pytest.raises(InvalidDataError, match="method must be 'backprojection' for site tiles"):
        check_config(ReconstructConfig(method="pseudo3d", tile_m=1.0))
    with pytest.raises(InvalidDataError, match="method must be 'backprojection' or 'pseudo3d'"):
        check_config(ReconstructConfig(method="kirchhoff3d"))
    # lines turned 30 deg off the axes
    c, s_ = np.cos(np.radians(30)), np.sin(np.radians(30))
    turned = grid_lines.positions_xyz @ np.array([[c, s_, 0], [-s_, c, 0], [0, 0, 1]])
    with pytest.raises(InvalidDataError, match="pseudo-3D needs lines along x or y; line 0 .* 30 deg"):
        reconstruct(grid_lines.replace(positions_xyz=turned), ReconstructConfig(eps_r=EPS, method="pseudo3d"))


def test_reconstruct_names_its_stages_for_whoever_times_them(tmp_path):
    """Under gpr3d.core.timing.collect: prepare, grid, migrate, (noise map with boxes), fold, envelope, targets, in
    that order, each once; writing adds the volume and the VTI. Nothing is collected without a collector."""
    from gpr3d.core.timing import collect

    s = _profile([_crossing(0.6, 0.3)], n=101, length=1.0)
    cfg = ReconstructConfig(spacing_m=0.02, max_depth_m=0.5)
    with pytest.warns(GeometryWarning), collect(compile_times=False) as t:
        rec = reconstruct(s, cfg)
    assert list(t.seconds) == ["prepare", "grid", "migrate", "fold", "envelope", "targets"]
    assert set(t.counts.values()) == {1}
    with pytest.warns(GeometryWarning), collect(compile_times=False) as t:
        reconstruct(s, cfg, boxes=[[10, 1e-9, 90, 8e-9]])
    assert list(t.seconds) == ["prepare", "grid", "migrate", "noise map", "fold", "envelope", "targets"]
    with collect(compile_times=False) as t:
        write_reconstruction(rec, tmp_path / "out", source="line")
    assert list(t.seconds) == ["write volume", "write vti"]


@pytest.mark.parametrize("f_hz, eps, want, kept", [
    (500e6, 9.0, 0.020, False),  # c / (500 MHz x 3) = 19.99 cm: 2.0 cm to the millimetre
    (400e6, 6.0, 0.031, False),  # 30.6 cm / 10
    (100e6, 11.316, 0.089, False),  # 89.1 cm / 10 (the real 100 MHz grid, DepthNet's eps_r)
    (250e6, 4.0, 0.06, False),  # 59.96 cm / 10
    (1.6e9, 6.0, 0.02, True),  # 7.65 cm / 10 = 8 mm: not finer than 2 cm
    (800e6, 6.0, 0.02, True),  # 1.5 cm: 2 cm
    (10e6, 1.0, 0.5, True),  # 30 m / 10: the largest voxel kept
    (0.5, 9.0, 0.5, True),  # half a hertz is still a frequency: 0.5 m
])
def test_the_voxel_follows_the_antenna_s_wavelength_in_the_ground(f_hz, eps, want, kept):
    from gpr3d.core.units import C0
    from gpr3d.migration.reconstruct import voxel_spacing_m

    spacing, how = voxel_spacing_m(f_hz, eps)
    assert spacing == pytest.approx(want, abs=1e-12)
    wavelength = C0 / (f_hz * np.sqrt(eps))
    assert how == (f"a tenth of the {f_hz / 1e6:g} MHz wavelength in the host (eps_r {eps:.3g}: {wavelength:.3g} m), "
                   "to the millimetre" + (", kept to 0.02..0.5 m" if kept else ""))


@pytest.mark.parametrize("f_hz", [None, 0.0, float("nan")])
def test_a_record_without_a_frequency_keeps_two_centimetre_voxels(f_hz):
    from gpr3d.migration.reconstruct import voxel_spacing_m

    assert voxel_spacing_m(f_hz, 9.0) == (0.02, "0.02 m: the record names no antenna frequency")


@pytest.mark.parametrize("method", ["pseudo3d", "backprojection"])
def test_reconstruct_at_its_default_sizes_voxels_by_the_data_and_says_so(grid_lines, method, tmp_path):
    """The lines' 800 MHz in eps_r 6 keep 2 cm voxels (a tenth of 15.3 cm is finer); the same lines said to be
    recorded at 400 MHz get 3.1 cm ones, the pipe where it is; a given spacing is kept."""
    rec = reconstruct(grid_lines, ReconstructConfig(max_depth_m=0.6, method=method))
    assert rec.grid.dx == rec.grid.dy == rec.grid.dd == pytest.approx(0.02, abs=1e-12)
    assert rec.spacing["how"].endswith("kept to 0.02..0.5 m")
    low = grid_lines.copy()
    low.frequency_hz = 400e6
    said = []
    rec = reconstruct(low, ReconstructConfig(max_depth_m=0.6, method=method), log=said.append)
    assert "voxels of 3.1 cm: a tenth of the 400 MHz wavelength in the host (eps_r 6: 0.306 m), to the millimetre" in said
    assert rec.grid.dx == rec.grid.dy == rec.grid.dd == pytest.approx(0.031, abs=1e-12)
    assert rec.config["spacing_m"] == pytest.approx(0.031, abs=1e-12)
    assert rec.spacing == {"spacing_m": 0.031, "how": "a tenth of the 400 MHz wavelength in the host (eps_r 6: "
                                                      "0.306 m), to the millimetre"}
    best = max((t for t in rec.targets if t.kind == "line"), key=lambda t: t.length_m)
    assert np.all(np.abs(np.array(best.points_xyz)[:, 0] - 0.8) < 0.035)
    assert best.depth_m == pytest.approx(0.3, abs=0.035)
    write_reconstruction(rec, tmp_path, source="grid")
    assert json.loads((tmp_path / "config.json").read_text())["spacing"] == rec.spacing
    given = reconstruct(grid_lines, ReconstructConfig(spacing_m=0.03, max_depth_m=0.6, method=method))
    assert given.grid.dx == 0.03 and given.spacing == {"spacing_m": 0.03, "how": "given"}


def test_a_tile_smaller_than_ten_data_sized_voxels_is_refused_before_migrating(grid_lines):
    low = grid_lines.copy()
    low.frequency_hz = 400e6
    with pytest.raises(InvalidDataError, match=r"^tile_m must be at least 10 of this record's voxels \(0\.031 m: a "
                                               r"tenth of the 400 MHz wavelength .*\), so 0\.31 m or more; got 0\.3$"):
        reconstruct(low, ReconstructConfig(max_depth_m=0.6, tile_m=0.3))
    # ten voxels exactly: taken, the tiles' image the one pass's
    tiled = reconstruct(low, ReconstructConfig(max_depth_m=0.6, tile_m=10 * 0.031))
    whole = reconstruct(low, ReconstructConfig(max_depth_m=0.6))
    np.testing.assert_allclose(tiled.envelope, whole.envelope, rtol=0, atol=1e-5 * whole.envelope.max())
