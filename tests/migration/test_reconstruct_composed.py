"""reconstruct() (back projection) composed from its parts in the test: the operator with every setting passed on,
the boxes' mask and noise map, the fold normalisation, the envelope and the target extraction; the site-tile path
gives the same; a straight profile goes to its vertical plane."""

import math
import re
import warnings
from dataclasses import asdict

import numpy as np
import pytest

from gpr3d.core.errors import GeometryWarning, InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.survey import Survey
from gpr3d.migration.masking import box_mask, image_envelope
from gpr3d.migration.operator import BackProjection, antenna_positions
from gpr3d.migration.reconstruct import ProfileFrame, ReconstructConfig, reconstruct
from gpr3d.migration.targets import extract_profile_targets, extract_targets

C = 299792458.0


def _area_survey(seed=0, n=60):
    """Traces scattered over a 0.4 x 0.3 m patch with headings, an offset and time zero; random data."""
    rng = np.random.default_rng(seed)
    pos = np.c_[rng.uniform(0, 0.4, n), rng.uniform(0, 0.3, n), rng.uniform(-0.01, 0.01, n)]
    return Survey(data=rng.standard_normal((n, 70)).astype(np.float32), dt_s=0.05e-9, t0_s=0.4e-9, offset_m=0.04,
                  positions_xyz=pos, orientations_quat_wxyz=quat_from_yaw(rng.uniform(0, 6.28, n)),
                  frequency_hz=1.2e9, eps_r=7.0)


def _composed(s, cfg, boxes=None):
    eps = cfg.eps_r or s.eps_r
    v = C / math.sqrt(eps)
    depth = cfg.max_depth_m or 0.5 * v * (s.n_samples * s.dt_s - s.t0_s - 2 * cfg.air_gap_m / C) * 0.95
    grid = Grid3D.covering(s.positions_xyz, depth_m=depth, spacing_m=cfg.spacing_m,
                           depth_spacing_m=cfg.depth_spacing_m, pad_m=cfg.pad_m)
    tx, rx = antenna_positions(s.positions_xyz, s.orientations_quat_wxyz, s.offset_m)
    op = BackProjection(grid, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=s.t0_s, eps_r=eps,
                        aperture_deg=cfg.aperture_deg, aperture_m=cfg.aperture_m, obliquity=cfg.obliquity,
                        spreading=cfg.spreading, air_gap_m=cfg.air_gap_m)
    data, noise = s.data, None
    if boxes is not None:
        mask = box_mask(s.n_traces, s.n_samples, s.dt_s, boxes, taper_traces=cfg.taper_traces)
        data = s.data * mask
        noise = image_envelope(op.adjoint(s.data * (1 - mask)))
    image = op.adjoint(data)
    fold = None
    if cfg.normalize != "none":
        fold = op.adjoint(np.ones_like(s.data))
        norm = np.maximum(fold, 0.05 * fold.max())
        norm = np.sqrt(norm) if cfg.normalize == "sqrt_fold" else norm
        image = image / norm
        noise = None if noise is None else noise / norm
    env = image_envelope(image)
    band = max(2 * 2.0 * max(grid.dx, grid.dy), 0.5 * v / s.frequency_hz)
    targets = extract_targets(env, grid, threshold=cfg.threshold, min_line_m=cfg.min_line_m, band_m=band,
                              min_depth_m=cfg.min_target_depth_m)
    return grid, image, env, fold, noise, targets


CASES = [
    (dict(eps_r=5.0, spacing_m=0.03, aperture_deg=35.0, obliquity=False, spreading=True, normalize="fold",
          max_depth_m=0.2, depth_spacing_m=0.01, pad_m=0.05, threshold=0.4, min_line_m=0.1,
          min_target_depth_m=0.04), None),
    (dict(spacing_m=0.04, aperture_deg=None, obliquity=True, spreading=False, normalize="sqrt_fold",
          air_gap_m=0.05, taper_traces=1.0), [[3, 0.5e-9, 40, 2.5e-9]]),
    (dict(eps_r=9.0, spacing_m=0.04, normalize="none", min_line_m=0.05), [[0, 0.0, 59, 1.5e-9]]),
    (dict(spacing_m=0.03, aperture_deg=60.0, aperture_m=0.12, obliquity=True, spreading=True, min_line_m=0.05),
     [[3, 0.5e-9, 40, 2.5e-9]]),
    (dict(spacing_m=0.03, aperture_deg=None, aperture_m=0.1, min_line_m=0.05), None),
]


@pytest.mark.parametrize("kw, boxes", CASES)
def test_reconstruct_is_composed_of_its_parts(kw, boxes):
    s = _area_survey()
    cfg = ReconstructConfig(time_zero="none", remove_background=False, **kw)
    rec = reconstruct(s, cfg, boxes=boxes)
    grid, image, env, fold, noise, targets = _composed(s, cfg, boxes)
    assert rec.grid == grid and rec.frame is None
    scale = np.abs(image).max()
    np.testing.assert_allclose(rec.image, image, atol=2e-4 * scale)
    np.testing.assert_allclose(rec.envelope, env, atol=2e-4 * scale)
    if fold is None:
        assert rec.fold is None
    else:
        np.testing.assert_allclose(rec.fold, fold, rtol=1e-4, atol=1e-4 * fold.max())
    if noise is None:
        assert rec.noise_map is None
    else:
        np.testing.assert_allclose(rec.noise_map, noise, atol=2e-4 * noise.max())
    assert [(t.kind, t.n_voxels) for t in rec.targets] == [(t.kind, t.n_voxels) for t in targets]
    assert rec.eps_r == (kw.get("eps_r") or 7.0) and rec.n_traces == 60 and rec.config == asdict(cfg)
    assert set(rec.timings_s) == {"prepare", "migrate"} and 0 <= rec.timings_s["prepare"] < 60
    assert rec.updates_per_s == pytest.approx(60 * grid.size / rec.timings_s["migrate"], rel=1e-9, abs=0)


@pytest.mark.parametrize("method", ["backprojection", "pseudo3d"])
def test_an_image_alone_skips_the_noise_map_and_the_targets_and_keeps_the_rest(monkeypatch, method):
    """with_noise_map / with_targets False (what the focus search asks): the same image, envelope and fold as the
    whole reconstruction, no noise map, no targets, and the data outside the boxes never migrated."""
    if method == "pseudo3d":  # a grid of lines along x (pseudo-3D's input)
        xs = np.tile(np.linspace(0.0, 0.4, 30), 4)
        ys = np.repeat([0.0, 0.1, 0.2, 0.3], 30)
        rng = np.random.default_rng(3)
        s = Survey(data=rng.standard_normal((120, 70)).astype(np.float32), dt_s=0.05e-9, offset_m=0.0,
                   positions_xyz=np.c_[xs, ys, np.zeros(120)], frequency_hz=1.2e9, eps_r=7.0)
        boxes = [[3, 0.5e-9, 100, 2.5e-9]]
    else:
        s = _area_survey()
        boxes = [[3, 0.5e-9, 40, 2.5e-9]]
    cfg = ReconstructConfig(time_zero="none", remove_background=False, spacing_m=0.04, min_line_m=0.05,
                            method=method)
    whole = reconstruct(s, cfg, boxes=boxes)
    assert whole.noise_map is not None and whole.targets  # (the case has both to leave out)
    import gpr3d.migration.operator as operator
    import gpr3d.migration.traditional as traditional

    seen = []  # the data each migration is given: inside the boxes only
    adjoint, p3d = operator.BackProjection.adjoint, traditional.pseudo3d
    monkeypatch.setattr(operator.BackProjection, "adjoint",
                        lambda op, data, **kw: seen.append(np.array(data)) or adjoint(op, data, **kw))
    monkeypatch.setattr(traditional, "pseudo3d", lambda sv, *a, **kw: seen.append(np.array(sv.data)) or p3d(sv, *a, **kw))
    for nm, tg in ((False, True), (True, False), (False, False)):
        seen.clear()
        part = reconstruct(s, cfg, boxes=boxes, with_noise_map=nm, with_targets=tg)
        np.testing.assert_array_equal(part.image, whole.image)
        np.testing.assert_array_equal(part.envelope, whole.envelope)
        if method == "backprojection":
            np.testing.assert_array_equal(part.fold, whole.fold)
        assert (part.noise_map is not None) == nm
        if nm:
            np.testing.assert_array_equal(part.noise_map, whole.noise_map)
        else:  # nothing outside the boxes was migrated: each migration saw the masked data (zero out there)
            assert seen and all(not d[:, :8].any() for d in seen)  # (the mask starts at sample 8)
        assert [(t.kind, t.n_voxels) for t in part.targets] == (
            [(t.kind, t.n_voxels) for t in whole.targets] if tg else [])


def test_site_tiles_in_this_process_give_the_same_volumes(tmp_path):
    s = _area_survey()
    boxes = [[3, 0.5e-9, 40, 2.5e-9]]
    base = dict(time_zero="none", remove_background=False, spacing_m=0.04, normalize="sqrt_fold")
    whole = reconstruct(s, ReconstructConfig(**base), boxes=boxes)
    tiled = reconstruct(s, ReconstructConfig(**base, tile_m=0.15, checkpoint=str(tmp_path / "ck")), boxes=boxes)
    np.testing.assert_allclose(tiled.image, whole.image, atol=1e-5 * np.abs(whole.image).max())
    np.testing.assert_allclose(tiled.noise_map, whole.noise_map, atol=1e-5 * whole.noise_map.max())
    np.testing.assert_allclose(tiled.fold, whole.fold, rtol=1e-5, atol=1e-5)
    assert {p.name for p in (tmp_path / "ck").iterdir()} == {"image", "noise"}  # each migration keeps its tiles


def test_time_zero_shifts_the_boxes_with_the_record():
    """Boxes are in the recording's times; time zero cuts the front of the record, and the boxes move with it:
    the masked image equals the one made from the cut record with the boxes moved by hand."""
    s = _area_survey()
    data = s.data.copy()
    data[:, 8] += 30.0  # a direct wave at sample 8 for time zero to find
    s = s.replace(data=data, t0_s=0.0)
    cfg = ReconstructConfig(time_zero="peak", remove_background=False, spacing_m=0.04, normalize="none")
    boxes = [[3, 1.0e-9, 40, 2.5e-9]]
    rec = reconstruct(s, cfg, boxes=boxes)
    cut = s.time_zero(method="peak", search_s=min(s.time_window_s / 4, 10e-9))
    shift = float(cut.history[-1]["result"]["t0_s"]) - cut.t0_s
    assert shift > 4 * s.dt_s  # time zero cut several samples
    ref = reconstruct(cut, ReconstructConfig(time_zero="none", remove_background=False, spacing_m=0.04,
                                             normalize="none"),
                      boxes=[[3, 1.0e-9 - shift, 40, 2.5e-9 - shift]])
    np.testing.assert_allclose(rec.image, ref.image, atol=1e-5 * np.abs(ref.image).max())


def test_a_straight_profile_is_migrated_in_its_vertical_plane():
    rng = np.random.default_rng(3)
    n = 50
    along = np.linspace(0, 0.6, n)
    d = np.array([0.8, 0.6])
    xy = np.array([2.0, 1.0]) + along[:, None] * d + rng.normal(0, 0.002, (n, 2))
    s = Survey(data=rng.standard_normal((n, 60)).astype(np.float32), dt_s=0.05e-9, positions_xyz=np.c_[xy, np.zeros(n)],
               orientations_quat_wxyz=quat_from_yaw(np.full(n, np.arctan2(0.6, 0.8))), offset_m=0.04,
               frequency_hz=1e9, eps_r=6.0)
    cfg = ReconstructConfig(time_zero="none", remove_background=False, spacing_m=0.02, normalize="none",
                            threshold=0.5, min_line_m=0.2, min_target_depth_m=0.02)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = reconstruct(s, cfg)
    (w,) = [c for c in caught if issubclass(c.category, GeometryWarning)]
    assert re.match(r"the antenna positions span only \d\.\d cm across their main direction \(one straight profile, "
                    r"0\.60 m long\)", str(w.message))
    # reported at the caller's line (under mutmut, the trampoline that stands in one call frame)
    assert w.filename == __file__ or w.filename.endswith("trampoline.py")
    fr = ProfileFrame.fit(s.positions_xyz)
    assert rec.frame == fr and rec.grid.ny == 1 and rec.grid.y0 == 0.0
    line = fr.to_line(s.positions_xyz)
    v = C / math.sqrt(6.0)
    grid = Grid3D.covering(line, depth_m=0.5 * v * 60 * 0.05e-9 * 0.95, spacing_m=0.02, pad_m=0.1)
    assert (rec.grid.x0, rec.grid.nx, rec.grid.nd) == (grid.x0, grid.nx, grid.nd)
    tx, rx = antenna_positions(s.positions_xyz, s.orientations_quat_wxyz, 0.04)
    op = BackProjection(Grid3D(grid.x0, 0.0, grid.d0, grid.dx, grid.dy, grid.dd, grid.nx, 1, grid.nd),
                        fr.to_line(tx), fr.to_line(rx), dt_s=s.dt_s, n_samples=60, eps_r=6.0, aperture_deg=50.0,
                        obliquity=True, spreading=True)
    img = op.adjoint(s.data)
    np.testing.assert_allclose(rec.image, img, atol=2e-4 * np.abs(img).max())
    env = image_envelope(img)
    want = extract_profile_targets(env[:, 0, :], rec.grid.x, rec.grid.depth, threshold=0.5, min_line_m=0.2,
                                   min_depth_m=0.02)
    assert len(rec.targets) == len(want) > 0
    for t, u in zip(rec.targets, want):  # along the line -> the world
        assert t.extra["along_m"] == [p[0] for p in u.points_xyz]
        np.testing.assert_allclose([p[:2] for p in t.points_xyz], fr.to_world([p[0] for p in u.points_xyz]))
    with pytest.raises(InvalidDataError, match=r"^the antenna positions all lie within 3\.0 cm: no profile and no "
                                               r"area to image$"):
        reconstruct(s.replace(positions_xyz=np.c_[np.linspace(0, 0.03, n), np.zeros((n, 2))]), cfg)


def test_reconstruct_refusals_in_full():
    s = _area_survey()
    with pytest.raises(InvalidDataError, match="^no eps_r: the survey has none; give --eps-r$"):
        reconstruct(s.replace(eps_r=None), ReconstructConfig())
    with pytest.raises(InvalidDataError, match=r"^no boxes: nothing to migrate inside them \(give boxes=None for the "
                                               r"whole record\)$"):
        reconstruct(s, ReconstructConfig(), boxes=[])
    with pytest.raises(InvalidDataError, match=r"^the survey has no antenna positions: give --poses \(a TUM file, "
                                               r"one pose per trace\)$"):
        reconstruct(s.replace(positions_xyz=None, orientations_quat_wxyz=None), ReconstructConfig())
    # a box starting after the record's end (3.5 ns) is refused: are its times in seconds?
    with pytest.raises(InvalidDataError, match=r"^box 0 \[0, 3\.6e-09, 10, 5e-09\] lies outside the data \(60 traces, "
                                               r"3\.5 ns\): are its times in seconds\?$"):
        reconstruct(s, ReconstructConfig(), boxes=[[0, 3.6e-9, 10, 5e-9]])
    # eps_r 1 (air) is a permittivity
    assert reconstruct(s, ReconstructConfig(eps_r=1.0, time_zero="none", spacing_m=0.05)).eps_r == 1.0
