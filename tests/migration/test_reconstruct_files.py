"""What write_reconstruction puts on disk, read back value by value, and the profile frame's geometry by hand."""

import json
import math

import numpy as np
import pytest

from gpr3d.core.grid import Grid3D
from gpr3d.io.volume import read_volume
from dataclasses import asdict

from gpr3d.migration.reconstruct import (ProfileFrame, Reconstruction, ReconstructConfig, cross_line_extent,
                                         write_reconstruction)
from gpr3d.migration.targets import Target3D


def _result(frame=None, noise=True):
    g = Grid3D(1.0, 2.0, 0.0, 0.05, 0.05, 0.02, 6, 5, 8)
    rng = np.random.default_rng(0)
    img = rng.standard_normal(g.shape).astype(np.float32)
    env = np.abs(img) + 0.1
    nm = (0.5 * env).astype(np.float32) if noise else None
    t = [Target3D("line", [[1.0, 2.1, 0.06], [1.2, 2.1, 0.08]], 0.06, 0.9, 12),
         Target3D("point", [[1.1, 2.15, 0.1]], 0.1, 0.4, 3)]
    if frame is not None:  # a profile's targets keep their places along it
        t = [Target3D("point", [[1.1, 2.15, 0.1]], 0.1, 0.4, 3, {"along_m": [0.1], "across_m": [0.0]})]
    return Reconstruction(image=img, envelope=env, noise_map=nm, fold=None, grid=g, targets=t, eps_r=6.5,
                          config=asdict(ReconstructConfig(spacing_m=0.05)), n_traces=40, timings_s={"migrate": 1.5},
                          updates_per_s=None,
                          eps_r_source="DepthNet", frame=frame)


def test_everything_written_reads_back(tmp_path):
    res = _result()
    out = tmp_path / "a" / "b"  # parents are made
    names = write_reconstruction(res, out, source="site.dzt")
    assert {"volume.h5", "volume.vti", "targets.json", "config.json"} <= set(names)
    vol = read_volume(out / "volume.h5")
    assert vol.grid == res.grid
    for k in ("image", "envelope", "noise_map"):
        np.testing.assert_array_equal(vol.arrays[k], getattr(res, k))
    assert vol.attrs["eps_r"] == 6.5 and vol.attrs["source"] == "site.dzt" and "frame_json" not in vol.attrs
    assert json.loads((out / "targets.json").read_text()) == {"targets": [
        {"name": "T1", "kind": "line", "points_xyz": [[1.0, 2.1, 0.06], [1.2, 2.1, 0.08]], "depth_m": 0.06,
         "score": 0.9},
        {"name": "T2", "kind": "point", "points_xyz": [[1.1, 2.15, 0.1]], "depth_m": 0.1, "score": 0.4}]}
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["source"] == "site.dzt" and cfg["eps_r"] == 6.5 and cfg["eps_r_source"] == "DepthNet"
    assert cfg["config"] == asdict(ReconstructConfig(spacing_m=0.05)) and cfg["grid"] == res.grid.to_dict()
    assert cfg["frame"] is None and cfg["timings_s"] == {"migrate": 1.5} and "gpr3d" in cfg
    vti = (out / "volume.vti").read_bytes()
    assert b'Name="envelope"' in vti and b'Name="noise_map"' in vti
    # without a noise map, none is written
    write_reconstruction(_result(noise=False), tmp_path / "c")
    assert "noise_map" not in read_volume(tmp_path / "c" / "volume.h5").arrays
    assert b'Name="noise_map"' not in (tmp_path / "c" / "volume.vti").read_bytes()


def test_a_profile_s_frame_is_written_and_maps_points_to_the_world(tmp_path):
    d = (math.cos(0.3), math.sin(0.3))
    fr = ProfileFrame((10.0, 20.0), d)
    res = _result(frame=fr)
    write_reconstruction(res, tmp_path)
    assert json.loads(read_volume(tmp_path / "volume.h5").attrs["frame_json"]) == {
        "kind": "profile", "origin_xy": [10.0, 20.0], "direction_xy": list(d)}
    assert json.loads((tmp_path / "config.json").read_text())["frame"] == fr.to_dict()
    # voxel (i, j, k) of the profile grid: along = x, across = y, to the world through the frame
    idx = np.array([[2, 1, 3], [0, 4, 7]])
    pts = res.grid.points(idx)
    want = np.column_stack([10.0 + pts[:, 0] * d[0] - pts[:, 1] * d[1], 20.0 + pts[:, 0] * d[1] + pts[:, 1] * d[0],
                            pts[:, 2]])
    np.testing.assert_allclose(res.world_points(idx), want, atol=1e-12)
    np.testing.assert_allclose(_result().world_points(idx), pts)  # no frame: the grid's own coordinates


def test_profile_frame_fit_and_back():
    """A profile driven from the north-east to the south-west: its direction points from the first trace to the
    last, its origin is the rearmost position's foot on the line, and world -> line -> world is the identity."""
    rng = np.random.default_rng(2)
    s = np.linspace(0.0, 3.0, 31)
    d = np.array([-0.6, -0.8])
    xy = np.array([5.0, 7.0]) + s[:, None] * d + rng.normal(0, 0.002, (31, 2))
    p = np.c_[xy, rng.normal(0, 0.01, 31)]
    fr = ProfileFrame.fit(p)
    np.testing.assert_allclose(fr.direction_xy, d, atol=2e-3)
    line = fr.to_line(p)
    assert line[:, 0].min() == pytest.approx(0.0, abs=1e-12) and line[-1, 0] == pytest.approx(3.0, abs=0.01)
    np.testing.assert_allclose(line[:, 2], p[:, 2])
    np.testing.assert_allclose(fr.to_world(line[:, 0], line[:, 1]), xy, atol=1e-12)
    # across is to the left of the direction: (-d_y, d_x)
    np.testing.assert_allclose(fr.to_world([1.0], 0.5), [np.array(fr.origin_xy) + 1.0 * np.array(fr.direction_xy)
                                                          + 0.5 * np.array([-fr.direction_xy[1], fr.direction_xy[0]])])


def test_cross_line_extent_by_hand():
    assert cross_line_extent(np.zeros((2, 3))) == 0.0  # two points make no width
    three = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.3, 5.0]])
    # a line with one point 0.3 m off it: the width across the main direction
    ext = cross_line_extent(three)
    c = three[:, :2] - three[:, :2].mean(axis=0)
    u = np.linalg.eigh(c.T @ c)[1][:, 0]  # the minor axis
    assert ext == pytest.approx(float((c @ u).max() - (c @ u).min()), rel=1e-9, abs=0) and 0.14 < ext < 0.3
    grid = np.array([[x, y, 0.0] for x in range(4) for y in (0.0, 0.5)])
    assert cross_line_extent(grid) == pytest.approx(0.5)
