"""reconstruct() ends its grid where the signal ends (gpr3d.processing.signal): a shallow pipe under a long record
with receiver noise is imaged on a shallower grid, with the same image and targets where the pipe is; the choice
and its reason are in config.json and said once."""

import json

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.units import velocity_from_eps_r
from gpr3d.migration.reconstruct import ReconstructConfig, grid_depth_m, reconstruct, write_reconstruction
from gpr3d.processing.signal import signal_end
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model

EPS = 6.0
NS, WINDOW = 320, 30e-9


def _zigzag(n_lines=8, per=61, length=1.2, step=0.06, along=0.02):
    pos, yaw = [], []
    for k in range(n_lines):
        x = np.arange(per) * along * length / (per - 1) / along
        pos.append(np.c_[x if k % 2 == 0 else x[::-1], np.full(per, step * k), np.zeros(per)])
        yaw.append(np.full(per, 0.0 if k % 2 == 0 else np.pi))
    return np.concatenate(pos), quat_from_yaw(np.concatenate(yaw))


def _survey(pos, q, noise):
    scene = ForwardScene(eps_r=EPS, pipes=[Pipe((0.6, -0.5, -0.27), (0.6, 1.5, -0.27), 0.02)])
    data = forward_model(scene, pos, q, offset_m=0.05, frequency_hz=800e6, n_samples=NS, time_window_s=WINDOW,
                         air_wave=1.0, ground_wave=0.5, noise=noise, seed=5)
    return Survey(data=data, dt_s=WINDOW / NS, offset_m=0.05, frequency_hz=800e6, eps_r=EPS, positions_xyz=pos,
                  orientations_quat_wxyz=q)


@pytest.fixture(scope="module")
def noisy():
    pos, q = _zigzag()
    return _survey(pos, q, noise=0.02)


def test_a_shallow_pipe_under_a_long_record_gets_a_shallow_grid_and_the_same_image(noisy, tmp_path):
    said = []
    cfg = ReconstructConfig(spacing_m=0.03, signal_depth=True)
    cut = reconstruct(noisy, cfg, log=said.append)
    full = reconstruct(noisy, ReconstructConfig(spacing_m=0.03, signal_depth=False), log=said.append)
    v = velocity_from_eps_r(EPS)
    d = cut.depth
    assert d["how"] == "signal" and full.depth["how"] == "record" and "why" not in full.depth
    assert d["record_m"] == pytest.approx(full.grid.depth[-1], abs=0.03) and d["record_m"] > 1.6
    # the pipe's top at 0.25 m; its echo (and the direct wave's ringing) end within a few ns: the signal's end,
    # and the grid, lie between the pipe and the record's end
    assert 0.35 < d["depth_m"] < 0.7 * d["record_m"], d
    assert d["depth_m"] == pytest.approx(0.5 * v * d["signal"]["end_s"] - 0.5 * v * 0.0, abs=0.05)
    assert cut.grid.depth[-1] <= d["depth_m"] + 1e-9 and cut.grid.depth[-1] > d["depth_m"] - cut.grid.dd - 1e-9
    assert (cut.grid.nx, cut.grid.ny, cut.grid.d0) == (full.grid.nx, full.grid.ny, full.grid.d0)
    assert said == [f"depth range to {d['depth_m']:.2f} m of the record's {d['record_m']:.2f} m: {d['why']} "
                    "(--signal-depth)"]
    nd = cut.grid.nd
    # each voxel's sum does not depend on how deep the grid goes, and the fold's floor is the whole record's (its
    # largest fold found again): the same image, to float rounding
    ref = np.abs(full.image[:, :, :nd]).max()
    assert np.abs(cut.image - full.image[:, :, :nd]).max() < 1e-5 * ref
    assert cut.depth["fold_max"] == pytest.approx(float(full.fold.max()), rel=1e-6)
    assert float(cut.fold.max()) < 0.6 * cut.depth["fold_max"]  # (the cut grid's own: far from it)
    # the envelope along depth (a transform of each whole column) moves by a few hundredths of its peak at the ends
    # of the columns, at most a hundredth where the pipe is (every voxel over the target threshold)
    env_ref = np.abs(full.envelope).max()
    diff = np.abs(cut.envelope - full.envelope[:, :, :nd])
    target = full.envelope[:, :, :nd] >= 0.3 * env_ref
    assert target.sum() > 20 and diff[target].max() < 0.01 * env_ref and diff.max() < 0.05 * env_ref
    # the pipe: the same target, found the same way
    def lines(rec):
        return [(t.kind, np.round(t.points_xyz, 2).tolist()) for t in rec.targets if t.kind == "line"]
    assert lines(cut) and lines(cut) == lines(full)
    assert full.grid.size / cut.grid.size > 2  # the voxels saved (54 layers down to 25)
    write_reconstruction(cut, tmp_path / "out", source="zigzag")
    doc = json.loads((tmp_path / "out" / "config.json").read_text())
    assert doc["depth"] == json.loads(json.dumps(d)) and doc["config"]["signal_depth"] is True


def test_the_depth_follows_the_signal_not_a_fixed_share(noisy):
    pos, q = _zigzag()
    deeper = _survey(pos, q, noise=0.02)
    pipe2 = forward_model(ForwardScene(eps_r=EPS, pipes=[Pipe((0.3, -0.5, -1.02), (0.3, 1.5, -1.02), 0.02)]),
                          pos, q, offset_m=0.05, frequency_hz=800e6, n_samples=NS, time_window_s=WINDOW,
                          air_wave=0.0, ground_wave=0.0)
    deeper = deeper.replace(data=deeper.data + pipe2)
    a = reconstruct(noisy, ReconstructConfig(spacing_m=0.05, signal_depth=True)).depth
    b = reconstruct(deeper, ReconstructConfig(spacing_m=0.05, signal_depth=True)).depth
    assert b["how"] == "signal" and b["depth_m"] > 1.0 > a["depth_m"] + 0.1, (a, b)


def test_when_the_record_is_kept_whole_and_why(noisy):
    v = velocity_from_eps_r(EPS)
    prepared = noisy.time_zero(method="peak", search_s=10e-9).remove_background()
    # a depth given wins
    depth, info = grid_depth_m(prepared, ReconstructConfig(max_depth_m=0.9), v, noisy.positions_xyz)
    assert depth == 0.9 and info["how"] == "max_depth_m"
    # asked not to
    depth, info = grid_depth_m(prepared, ReconstructConfig(signal_depth=False), v, noisy.positions_xyz)
    assert info == {"depth_m": depth, "record_m": depth, "how": "record"}
    assert ReconstructConfig().signal_depth is False  # (asked for: the default images the whole record)
    assert grid_depth_m(prepared, ReconstructConfig(), v, noisy.positions_xyz) == (depth, info)
    # a record that ends within the pipe's echo: nothing to cut
    short = prepared.replace(data=prepared.data[:, :100])
    depth, info = grid_depth_m(short, ReconstructConfig(signal_depth=True), v, noisy.positions_xyz)
    assert info["how"] == "record" and info["why"] == "the signal reaches the record's end"
    # traces too far apart for neighbours to be compared (20 cm: over a quarter of the 15 cm wavelength)
    sparse = prepared.replace(positions_xyz=prepared.positions_xyz * 10)
    depth, info = grid_depth_m(sparse, ReconstructConfig(signal_depth=True), v, sparse.positions_xyz)
    assert info["how"] == "record" and info["why"].startswith("neighbouring traces lie 20.0 cm apart, over a quarter")
    said = []
    grid_depth_m(prepared, ReconstructConfig(signal_depth=True), v, noisy.positions_xyz, said.append)
    assert len(said) == 1 and said[0].startswith("depth range to ")
    # the signal's end as signal_end finds it, at half the two-way time
    from gpr3d.migration.refine import dominant_frequency_hz

    end = signal_end(prepared.data, prepared.dt_s, dominant_frequency_hz(prepared.data, prepared.dt_s))
    depth, info = grid_depth_m(prepared, ReconstructConfig(signal_depth=True), v, noisy.positions_xyz)
    assert depth == pytest.approx(0.5 * v * (end.end_s - prepared.t0_s)) and info["signal"] == end.to_dict()
    # an air gap takes its two-way time off
    depth_air, _ = grid_depth_m(prepared, ReconstructConfig(air_gap_m=0.1, signal_depth=True), v,
                                noisy.positions_xyz)
    assert depth - depth_air == pytest.approx(0.5 * v * 2 * 0.1 / 299792458.0)


@pytest.mark.parametrize("kw", [{}, {"air_gap_m": 0.05}, {"aperture_deg": 30.0}, {"obliquity": False},
                                {"depth_spacing_m": 0.02}])
def test_the_fold_s_floor_is_the_whole_record_s(noisy, kw):
    cut = reconstruct(noisy, ReconstructConfig(spacing_m=0.03, **kw, signal_depth=True))
    full = reconstruct(noisy, ReconstructConfig(spacing_m=0.03, signal_depth=False, **kw))
    assert cut.depth["how"] == "signal" and cut.grid.nd < full.grid.nd
    # found on voxels of the whole-record grid (every third, then all about the 16 largest of those): its largest
    assert cut.depth["fold_max"] == pytest.approx(float(full.fold.max()), rel=1e-6)
    assert cut.depth["fold_max"] > 1.3 * float(cut.fold.max())  # (the cut grid's own would be a lower floor)


def test_the_depth_s_other_reasons_in_full(noisy):
    v = velocity_from_eps_r(EPS)
    prepared = noisy.time_zero(method="peak", search_s=10e-9).remove_background()
    record = 0.5 * v * (prepared.n_samples * prepared.dt_s - prepared.t0_s) * 0.95
    assert grid_depth_m(prepared, ReconstructConfig(max_depth_m=0.9), v, noisy.positions_xyz) == (
        0.9, {"depth_m": 0.9, "record_m": pytest.approx(record), "how": "max_depth_m"})
    # silence: no frequency to size the windows by
    quiet = prepared.replace(data=np.zeros_like(prepared.data))
    depth, info = grid_depth_m(quiet, ReconstructConfig(signal_depth=True), v, noisy.positions_xyz)
    assert info == {"depth_m": depth, "record_m": depth, "how": "record",
                    "why": "the traces carry no frequency to compare them by"}
    # a quarter wavelength: traces just inside it are compared, just outside it not
    from gpr3d.migration.refine import dominant_frequency_hz

    quarter = v / dominant_frequency_hz(prepared.data, prepared.dt_s) / 4
    step = float(np.median(np.linalg.norm(np.diff(noisy.positions_xyz[:, :2], axis=0), axis=1)))
    for scale, how in ((0.9, "signal"), (1.1, "record")):
        pos = noisy.positions_xyz * (scale * quarter / step)
        depth, info = grid_depth_m(prepared, ReconstructConfig(signal_depth=True), v, pos)
        assert info["how"] == how, (scale, info)
    assert info["why"] == (f"neighbouring traces lie {1.1 * quarter * 100:.1f} cm apart, over a quarter wavelength "
                           f"({quarter * 100:.1f} cm): their likeness cannot tell signal from noise")
    # time zero later than the first sample: the depth counts from it
    late = prepared.replace(t0_s=1e-9)
    d0, _ = grid_depth_m(prepared, ReconstructConfig(signal_depth=True), v, noisy.positions_xyz)
    d1, _ = grid_depth_m(late, ReconstructConfig(signal_depth=True), v, noisy.positions_xyz)
    assert d0 - d1 == pytest.approx(0.5 * v * 1e-9)


def test_the_signal_s_stages_are_timed(noisy):
    from gpr3d.core.timing import collect

    with collect(compile_times=False) as t:
        reconstruct(noisy, ReconstructConfig(spacing_m=0.05, signal_depth=True))
    assert list(t.seconds) == ["prepare", "signal depth", "grid", "migrate", "fold max", "fold", "envelope",
                               "targets"]
    with collect(compile_times=False) as t:
        reconstruct(noisy, ReconstructConfig(spacing_m=0.05, signal_depth=False))
    assert list(t.seconds) == ["prepare", "grid", "migrate", "fold", "envelope", "targets"]


def test_the_whole_record_s_fold_floor_keeps_the_aperture_radius(noisy):
    """With a radius narrower than the cone at depth (0.3 m), the largest fold searched over the whole record is
    that of the full-depth grid with the same radius, not the cone's alone (which is larger by far)."""
    cut = reconstruct(noisy, ReconstructConfig(spacing_m=0.03, signal_depth=True, aperture_m=0.3))
    full = reconstruct(noisy, ReconstructConfig(spacing_m=0.03, aperture_m=0.3))
    cone = reconstruct(noisy, ReconstructConfig(spacing_m=0.03))
    assert cut.depth["how"] == "signal" and cut.config["aperture_m"] == 0.3
    assert cut.depth["fold_max"] == pytest.approx(float(full.fold.max()), rel=1e-6)
    assert float(full.fold.max()) < 0.8 * float(cone.fold.max())
