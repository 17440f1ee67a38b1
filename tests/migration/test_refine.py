"""Coarse-to-fine imaging (gpr3d.migration.refine): refined voxels equal the whole image's, the others the coarse
columns interpolated; the marking, the stride and the frequency by hand; reconstruct with it on and off."""

import json
import time
from dataclasses import replace

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.survey import Survey
from gpr3d.migration import refine
from gpr3d.migration.config import ReconstructConfig
from gpr3d.migration.masking import image_envelope
from gpr3d.migration.operator import BackProjection, antenna_positions
from gpr3d.migration.reconstruct import check_config, normalise_by_fold, reconstruct, write_reconstruction
from gpr3d.simulation.forward import ForwardScene, Pipe, Sphere, forward_model
from gpr3d.simulation.paths import random_walk


def test_dominant_frequency_from_every_few_hundredth_trace():
    # 1024 traces: every second one is read (1024 // 512); the even ones carry 450 MHz, the odd ones a stronger
    # 300 MHz that a reading of every trace would pick
    dt = 0.05e-9
    t = np.arange(400) * dt
    data = np.empty((1024, 400))
    data[0::2] = np.sin(2 * np.pi * 450e6 * t)
    data[1::2] = 3 * np.sin(2 * np.pi * 300e6 * t)
    assert refine.dominant_frequency_hz(data, dt) == pytest.approx(450e6)
    assert refine.dominant_frequency_hz(data[:3], dt) == pytest.approx(300e6)  # 3 traces: all read


def test_dominant_frequency_of_a_known_tone():
    dt = 0.05e-9
    t = np.arange(400) * dt
    data = np.sin(2 * np.pi * 450e6 * t)[None, :] * np.linspace(1, 2, 30)[:, None] + 3.0  # (and an offset)
    # bins are 1 / (400 * 0.05 ns) = 50 MHz apart: 450 MHz is one of them
    assert refine.dominant_frequency_hz(data, dt) == pytest.approx(450e6)


@pytest.mark.parametrize("wavelength, spacing, n, want", [
    (0.20, 0.02, 100, 3),  # a third of 20 cm over 2 cm columns: 3.33 -> 3
    (0.24, 0.02, 100, 4),
    (0.60, 0.02, 100, 4),  # at most MAX_STRIDE
    (0.06, 0.02, 100, 1),  # columns within a third of a wavelength already
    (0.20, 0.02, 11, 1),   # too few columns for a coarse pass of 3
    (0.20, 0.02, 12, 3),   # just enough: four coarse columns' spans
    (0.13, 0.02, 100, 2),
])
def test_coarse_stride_from_the_wavelength(wavelength, spacing, n, want):
    g = Grid3D(0.0, 0.0, 0.02, spacing, spacing, 0.02, n, n + 3, 10)
    assert refine.coarse_stride(g, wavelength) == want


def test_marked_columns_by_hand(monkeypatch):
    # coarse columns every 2 fine ones (coarse c is fine 2c): 9 x 7 of them over 17 x 13 fine columns; one hot
    # coarse voxel at column (4, 3) (any depth: here 10), one exactly at the level at (8, 6), the rest far below
    monkeypatch.setattr(refine, "LATERAL_MARGIN", 0.0)
    grid = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 17, 13, 20)
    cenv = np.full((9, 7, 20), 0.01, np.float32)
    cenv[4, 3, 10] = 1.0
    cenv[8, 6, 2] = 0.5
    cols, ref, mc = refine.refine_columns(cenv, 2, grid, level=0.5, wavelength_m=0.08, reference_percentile=100)
    assert (ref, mc) == (1.0, 0)
    # fine column i takes coarse columns i // 2 and i // 2 + 1: coarse 4 <- fine 6, 7, 8, 9; coarse 3 <- 4, 5, 6, 7;
    # coarse 8 <- fine 14, 15, 16; coarse 6 <- fine 10, 11, 12 (at the level counts)
    want = np.zeros((17, 13), bool)
    want[6:10, 4:8] = True
    want[14:17, 10:13] = True
    np.testing.assert_array_equal(cols, want)
    # above every column's level: nothing; an envelope of zeros (no reference): every column
    assert not refine.refine_columns(cenv, 2, grid, level=1.5, wavelength_m=0.08, reference_percentile=100)[0].any()
    assert refine.refine_columns(np.zeros_like(cenv), 2, grid, level=0.5, wavelength_m=0.08)[0].all()
    # a lateral margin of a wavelength of 0.2 m over 4 cm coarse columns: 5 coarse columns each way
    monkeypatch.setattr(refine, "LATERAL_MARGIN", 1.0)
    assert refine.refine_columns(cenv, 2, grid, level=0.5, wavelength_m=0.2, reference_percentile=100)[2] == 5
    # one coarse column: the hot one widens to coarse 3..5 along x and 2..4 along y (fine 4..11 and 2..9)
    monkeypatch.setattr(refine, "LATERAL_MARGIN", 0.3)  # 0.3 x 0.08 m over 4 cm coarse columns -> 1
    cenv[8, 6, 2] = 0.0
    cols2, _, mc2 = refine.refine_columns(cenv, 2, grid, level=0.5, wavelength_m=0.08, reference_percentile=100)
    want2 = np.zeros((17, 13), bool)
    want2[4:12, 2:10] = True
    assert mc2 == 1
    np.testing.assert_array_equal(cols2, want2)


def test_marked_depth_ranges_by_hand():
    # coarse columns every 2 fine ones: 9 x 7 of them over 17 x 13 fine columns, 40 depths of 2 cm; coarse column
    # (4, 3) hot at depths 10 and 14, (5, 3) at 20 (exactly at the level), (8, 6) at 1; the rest far below
    grid = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 17, 13, 40)
    cenv = np.full((9, 7, 40), 0.01, np.float32)
    cenv[4, 3, [10, 14]] = 1.0
    cenv[5, 3, 20] = 0.5
    cenv[8, 6, 1] = 0.9
    # a margin of 0.5 x 0.1 m over 2 cm depths: 3 voxels (2.5 rounded up)
    ranges, ref = refine.refine_ranges(cenv, 2, grid, level=0.5, wavelength_m=0.1, margin_wavelengths=0.5,
                                       reference_percentile=100)
    assert ref == 1.0 and ranges.dtype == np.int32 and ranges.shape == (17, 13, 2)
    want = np.zeros((17, 13, 2), np.int32)
    # fine i takes coarse i // 2 and i // 2 + 1: coarse 4 <- fine 6..9, coarse 5 <- fine 8..11; coarse 3 <- 4..7
    want[6:8, 4:8] = (7, 18)     # coarse (4, 3) alone: depths 10..14, 3 more each way
    want[8:10, 4:8] = (7, 24)    # coarse (4, 3) and (5, 3): 10..20 and the margins
    want[10:12, 4:8] = (17, 24)  # coarse (5, 3) alone
    want[14:17, 10:13] = (0, 5)  # coarse (8, 6): depth 1, the margin cut at the top
    np.testing.assert_array_equal(ranges, want)
    # the margin cut at the bottom; no margin; nothing above the level
    cenv[4, 3, 39] = 1.0
    r2 = refine.refine_ranges(cenv, 2, grid, level=0.5, wavelength_m=0.1, margin_wavelengths=0.5,
                              reference_percentile=100)[0]
    assert tuple(r2[6, 4]) == (7, 40)
    r0 = refine.refine_ranges(cenv, 2, grid, level=0.5, wavelength_m=0.1, margin_wavelengths=0.0,
                              reference_percentile=100)[0]
    assert tuple(r0[6, 4]) == (10, 40) and tuple(r0[10, 4]) == (20, 21) and tuple(r0[0, 0]) == (0, 0)
    assert not refine.refine_ranges(cenv, 2, grid, level=1.5, wavelength_m=0.1, margin_wavelengths=0.5,
                                    reference_percentile=100)[0].any()
    # an envelope of zeros (no reference): every voxel
    everything = refine.refine_ranges(np.zeros_like(cenv), 2, grid, level=0.5, wavelength_m=0.1,
                                      margin_wavelengths=0.5)[0]
    assert (everything[..., 0] == 0).all() and (everything[..., 1] == 40).all()


def test_coarse_grid_and_interpolation_by_hand():
    # the coarse grid starts on the first fine column and reaches the last one: ceil((n - 1) / k) + 1 columns
    g = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 7, 8, 5)
    for n, k, want in ((7, 3, 3), (8, 3, 4), (10, 3, 4), (9, 2, 5), (10, 4, 4)):
        cg = refine._coarse_grid(replace(g, nx=n, ny=n), k)
        assert (cg.nx, cg.ny, cg.dx, cg.dy) == (want, want, pytest.approx(0.02 * k), pytest.approx(0.02 * k))
        assert (cg.x0, cg.y0, cg.d0, cg.dd, cg.nd) == (g.x0, g.y0, g.d0, g.dd, g.nd)
    # interpolation onto every column: fine 0..6 from coarse 0, 3, 6 (the last fine column is a coarse one)
    c = np.arange(3 * 2 * 4, dtype=np.float32).reshape(3, 2, 4) ** 2
    out = refine._interp(c, 3, 7, 4)
    want = RegularGridInterpolator((np.arange(3) * 3, np.arange(2) * 3), c)(
        np.stack(np.meshgrid(np.arange(7), np.arange(4), indexing="ij"), -1).reshape(-1, 2)).reshape(7, 4, 4)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, want, rtol=1e-6)
    # a single coarse column along an axis is copied to every fine one; two are interpolated between
    one = refine._interp(c[:1], 3, 3, 4)
    np.testing.assert_array_equal(one, np.broadcast_to(refine._upsample(c[:1], 3, 4, 1), (3, 4, 4)))
    np.testing.assert_allclose(refine._upsample(c[:2], 3, 4, 0)[1], c[0] + (c[1] - c[0]) / 3, rtol=1e-6)


def _sphere_survey(n=1500, seed=3):
    walk = random_walk(n, area=((0.0, 1.6), (0.0, 1.6)), step_m=0.02, turn_rate=0.1, seed=seed)
    sc = ForwardScene(eps_r=6.0, spheres=[Sphere((0.8, 0.7, -0.4), 0.05)])
    data = forward_model(sc, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.05, frequency_hz=600e6,
                         n_samples=160, time_window_s=12e-9)
    return walk, data


@pytest.mark.parametrize("margin", [refine.DEPTH_MARGIN, None, 0.0])
def test_refined_voxels_equal_the_whole_image_and_the_rest_are_the_coarse_columns_interpolated(margin):
    walk, data = _sphere_survey()
    tx, rx = antenna_positions(walk.positions_xyz, walk.orientations_quat_wxyz, 0.05)
    grid = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 80, 78, 40)
    op = BackProjection(grid, tx, rx, dt_s=12e-9 / 160, n_samples=160, eps_r=6.0, aperture_deg=45, obliquity=True,
                        spreading=True)
    d = data.astype(np.float32)
    whole, whole_fold = op.adjoint(d, with_fold=True)
    wl = 0.2  # a longer wavelength than the data's: stride 3
    img, fold, info = refine.refined_adjoint(op, d, with_fold=True, wavelength_m=wl, level=0.15,
                                             normalize="sqrt_fold", **({} if margin == refine.DEPTH_MARGIN else
                                                                      {"depth_margin": margin}))
    k = info["stride"]
    assert k == 3 and 0 < info["refined_fraction"] < 0.5
    # the ranges the pass used, rebuilt from the coarse envelope of the whole image's own coarse columns
    cx, cy = np.arange(0, grid.nx + k - 1, k), np.arange(0, grid.ny + k - 1, k)
    assert (len(cx), len(cy)) == tuple(info["coarse_grid"][:2])
    cop = op.on_grid(Grid3D(0.0, 0.0, 0.02, 0.06, 0.06, 0.02, len(cx), len(cy), 40))
    cimg, cfold = cop.adjoint(d, with_fold=True)
    in_grid = (cx < grid.nx)[:, None] & (cy < grid.ny)[None, :]
    np.testing.assert_allclose(cimg[:, :][np.ix_(cx < grid.nx, cy < grid.ny)], whole[np.ix_(cx[cx < grid.nx],
                               cy[cy < grid.ny])], atol=1e-5 * np.abs(whole).max())  # coarse columns are fine ones
    assert in_grid.any()
    cenv = image_envelope(normalise_by_fold(cimg, cfold, "sqrt_fold")[0])
    if margin is None:
        cols = refine.refine_columns(cenv, k, grid, level=0.15, wavelength_m=wl)[0]
        inside = np.broadcast_to(cols[..., None], grid.shape)
        assert info["refine"] == "whole columns" and info["refined_columns"] == pytest.approx(info["refined_fraction"])
    else:
        ranges = refine.refine_ranges(cenv, k, grid, level=0.15, wavelength_m=wl, margin_wavelengths=margin)[0]
        kk = np.arange(grid.nd)
        inside = (kk >= ranges[..., :1]) & (kk < ranges[..., 1:])
        assert info["refine"] == "depth ranges" and info["depth_margin_wavelengths"] == margin
        assert info["refined_columns"] == pytest.approx((ranges[..., 1] > ranges[..., 0]).mean())
        assert info["refined_fraction"] < info["refined_columns"]  # not every depth of the refined columns
    assert inside.mean() == pytest.approx(info["refined_fraction"])
    # the coarse columns keep the coarse pass's values at every depth, to the bit (the fine pass leaves them out)
    np.testing.assert_array_equal(img[::k, ::k], cimg[: len(range(0, grid.nx, k)), : len(range(0, grid.ny, k))])
    np.testing.assert_array_equal(fold[::k, ::k], cfold[: len(range(0, grid.nx, k)), : len(range(0, grid.ny, k))])
    assert info["fine_fraction"] < info["refined_fraction"]
    peak = np.abs(whole).max()
    np.testing.assert_allclose(img[inside], whole[inside], atol=1e-5 * peak)
    np.testing.assert_allclose(fold[inside], whole_fold[inside], atol=1e-5 * whole_fold.max())
    # elsewhere: the coarse image, interpolated across columns (scipy's bilinear interpolation)
    want = RegularGridInterpolator((cx, cy), cimg)(np.stack(np.meshgrid(np.arange(grid.nx), np.arange(grid.ny),
                                                                        indexing="ij"), -1).reshape(-1, 2))
    want = want.reshape(grid.shape)
    np.testing.assert_allclose(img[~inside], want[~inside], atol=1e-5 * peak)
    wfold = RegularGridInterpolator((cx, cy), cfold)(np.stack(np.meshgrid(np.arange(grid.nx), np.arange(grid.ny),
                                                                          indexing="ij"), -1).reshape(-1, 2))
    np.testing.assert_allclose(fold[~inside], wfold.reshape(grid.shape)[~inside], atol=1e-5 * whole_fold.max())
    # the sphere's focus is refined, and the refined image is the whole one where the energy is
    env = image_envelope(whole)
    assert inside[np.unravel_index(np.argmax(env), env.shape)]
    assert inside[env >= 0.5 * env.max()].all()


@pytest.mark.parametrize("step, n, want", [
    (0.02, 3000, 2),   # a quarter of 20 cm over 2 cm along the path: 2.5 -> 2
    (0.01, 3000, 4),   # 5, at most MAX_TRACE_STEP
    (0.025, 3000, 2),  # exactly 2
    (0.03, 3000, 1),   # 1.67: every trace
    (0.06, 3000, 1),
    (0.02, 1999, 1),   # fewer than MIN_TRACES_TO_THIN: every trace
    (0.02, 2000, 2),
    (0.0, 3000, 4),    # standing still
])
def test_coarse_trace_step_from_the_midpoints_spacing_along_the_path(step, n, want):
    assert refine.MIN_TRACES_TO_THIN == 2000 and refine.MAX_TRACE_STEP == 4
    s = np.arange(n) * step
    # lines 0.5 m apart, back and forth, 0.3 m long each: the jumps between lines are a few in every hundred traces
    per = max(int(round(0.3 / step)), 1) if step > 0 else n
    along = s - (np.arange(n) // per) * per * step
    mid = np.column_stack([along, 0.5 * (np.arange(n) // per), np.zeros(n)])
    tx = mid + [0.05, 0.0, 0.0]  # the antennas 10 cm apart, across the path: their midpoint is what counts
    rx = mid - [0.05, 0.0, 0.0]
    assert refine.coarse_trace_step(tx, rx, 0.2) == want
    # the same path with the antennas' offset turning with the cart: the same step
    turn = np.column_stack([0.05 * np.cos(np.arange(n)), 0.05 * np.sin(np.arange(n)), np.zeros(n)])
    assert refine.coarse_trace_step(mid + turn, mid - turn, 0.2) == want


def _spy_adjoints(monkeypatch) -> list:
    """Every BackProjection.adjoint call from now on, as ``(number of traces, depth_range)``."""
    calls = []
    adjoint = BackProjection.adjoint

    def spy(self, data, **kw):
        calls.append((self.n_traces, kw.get("depth_range")))
        return adjoint(self, data, **kw)

    monkeypatch.setattr(BackProjection, "adjoint", spy)
    return calls


def test_a_thinned_coarse_pass_refines_as_before_and_fills_the_rest_from_every_other_trace_scaled(monkeypatch):
    op, d = _sphere_op(n=1201, size=62, nd=40)
    grid, tx, rx = op.grid, op.tx, op.rx
    whole, whole_fold = op.adjoint(d, with_fold=True)
    calls = _spy_adjoints(monkeypatch)
    img, fold, info = refine.refined_adjoint(op, d, with_fold=True, wavelength_m=0.2, level=0.15, normalize="fold",
                                             trace_step=2)
    made = list(calls)
    k = info["stride"]
    assert k == 3 and info["coarse_trace_step"] == 2 and 0 < info["refined_fraction"] < 0.5
    # the coarse pass from every other trace (601 of 1201), its sums and fold scaled by 1201 / 601
    cx, cy = np.arange(0, grid.nx + k - 1, k), np.arange(0, grid.ny + k - 1, k)
    cop = BackProjection(Grid3D(grid.x0, grid.y0, 0.02, 0.06, 0.06, 0.02, len(cx), len(cy), 40), tx[::2], rx[::2],
                         dt_s=12e-9 / 160, n_samples=160, eps_r=6.0, aperture_deg=45)
    cimg, cfold = cop.adjoint(d[::2], with_fold=True)
    cimg *= 1201 / 601
    cfold *= 1201 / 601
    cenv = image_envelope(normalise_by_fold(cimg, cfold, "fold")[0])
    ranges = refine.refine_ranges(cenv, k, grid, level=0.15, wavelength_m=0.2, margin_wavelengths=refine.DEPTH_MARGIN)[0]
    kk = np.arange(grid.nd)
    inside = (kk >= ranges[..., :1]) & (kk < ranges[..., 1:])
    assert inside.mean() == pytest.approx(info["refined_fraction"])
    # the coarse pass from 601 traces; the fine pass from every trace, the coarse columns' ranges included
    assert len(made) == 2 and made[0] == (601, None) and made[1][0] == 1201
    np.testing.assert_array_equal(made[1][1], ranges)
    assert info["fine_fraction"] == pytest.approx(info["refined_fraction"])
    assert inside[::k, ::k].any()
    peak = np.abs(whole).max()
    np.testing.assert_allclose(img[inside], whole[inside], atol=1e-5 * peak)  # the coarse columns' included
    np.testing.assert_allclose(fold[inside], whole_fold[inside], atol=1e-5 * whole_fold.max())
    grid_pts = np.stack(np.meshgrid(np.arange(grid.nx), np.arange(grid.ny), indexing="ij"), -1).reshape(-1, 2)
    want = RegularGridInterpolator((cx, cy), cimg)(grid_pts).reshape(grid.shape)
    np.testing.assert_allclose(img[~inside], want[~inside], atol=1e-5 * peak)
    wfold = RegularGridInterpolator((cx, cy), cfold)(grid_pts).reshape(grid.shape)
    np.testing.assert_allclose(fold[~inside], wfold[~inside], atol=1e-5 * whole_fold.max())
    # the thinned coarse image is close to the whole one on its columns: the scaling is right (not 0.5x or 2x)
    on = whole[::k, ::k]
    c = cimg[: on.shape[0], : on.shape[1]]
    assert np.abs(c - on).max() < 0.25 * peak
    assert float(np.sum(c * on) / np.sum(on * on)) == pytest.approx(1.0, abs=0.1)
    cf = cfold[: on.shape[0], : on.shape[1]]
    assert float(np.median(cf[cf > 0] / whole_fold[::k, ::k][cf > 0])) == pytest.approx(1.0, abs=0.05)


class _Clock:
    """A clock one second further on at every reading."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self):
        self.now += 1.0
        return self.now


@pytest.mark.parametrize("step", [0, -2, 1.5, True, "2"])
def test_a_trace_step_that_is_no_whole_number_from_1_is_named(step):
    op, d = _sphere_op(n=50, size=20, nd=10)
    with pytest.raises(InvalidDataError) as err:
        refine.refined_adjoint(op, d, with_fold=False, wavelength_m=0.2, level=0.15, normalize="fold",
                               trace_step=step)
    assert str(err.value) == ("trace_step must be a whole number >= 1 (every how many traces the coarse pass reads) "
                              f"or None, got {step!r}")


@pytest.mark.parametrize("m", [2, 3])
def test_a_thinned_coarse_pass_that_marks_too_much_is_completed_with_the_other_traces(monkeypatch, m):
    op, d = _sphere_op(n=1201, size=60)
    kw = dict(with_fold=True, wavelength_m=0.2, level=0.15, normalize="sqrt_fold")
    img1, fold1, info1 = refine.refined_adjoint(op, d, trace_step=1, **kw)
    monkeypatch.setattr(refine, "THIN_UP_TO", 1.0)
    thin = refine.refined_adjoint(op, d, trace_step=m, **kw)[2]
    marked = thin["refined_fraction"]
    assert thin["coarse_trace_step"] == m and "thinned" not in thin and marked != info1["refined_fraction"]
    monkeypatch.setattr(refine, "THIN_UP_TO", marked)  # exactly at the limit: kept thinned
    monkeypatch.setattr(refine, "time", _Clock())
    kept = refine.refined_adjoint(op, d, trace_step=m, **kw)[2]
    assert kept["coarse_trace_step"] == m
    assert kept["seconds"] == {"coarse": 1.0, "mark": 1.0, "fine": 1.0, "fill": 1.0}  # one reading each side
    monkeypatch.setattr(refine, "THIN_UP_TO", np.nextafter(marked, 0))
    calls = _spy_adjoints(monkeypatch)
    img, fold, info = refine.refined_adjoint(op, d, trace_step=m, **kw)
    # traces 0, m, 2m, ..., then the others; then the fine pass without the coarse columns, as from every trace
    part = len(range(0, 1201, m))
    assert [c[0] for c in calls] == [part, 1201 - part, 1201] and calls[0][1] is None and calls[1][1] is None
    assert not calls[2][1][::info["stride"], ::info["stride"]].any()
    assert info["coarse_trace_step"] == 1 and info["thinned"] == {"trace_step": m, "refined_fraction": marked}
    # the completion's pass and marking counted with the first ones'
    assert info["seconds"] == {"coarse": 2.0, "mark": 2.0, "fine": 1.0, "fill": 1.0}
    for key in ("refined_fraction", "refined_columns", "fine_fraction", "reference"):
        assert info[key] == pytest.approx(info1[key], rel=1e-6), key
    np.testing.assert_allclose(img, img1, rtol=0, atol=1e-5 * np.abs(img1).max())
    np.testing.assert_allclose(fold, fold1, rtol=0, atol=1e-5 * fold1.max())


def test_too_much_marked_migrates_every_voxel(monkeypatch):
    walk, data = _sphere_survey(600)
    tx, rx = antenna_positions(walk.positions_xyz, walk.orientations_quat_wxyz, 0.05)
    grid = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 60, 60, 30)
    op = BackProjection(grid, tx, rx, dt_s=12e-9 / 160, n_samples=160, eps_r=6.0, aperture_deg=45)
    d = data.astype(np.float32)
    whole, whole_fold = op.adjoint(d, with_fold=True)
    info0 = refine.refined_adjoint(op, d, with_fold=True, wavelength_m=0.2, level=0.15, normalize="fold")[2]
    marked = info0["refined_fraction"]
    assert 0 < marked < 1
    monkeypatch.setattr(refine, "MAX_REFINED", marked)  # exactly at the limit: still refined
    assert refine.refined_adjoint(op, d, with_fold=True, wavelength_m=0.2, level=0.15,
                                  normalize="fold")[2]["refined_fraction"] == marked
    monkeypatch.setattr(refine, "MAX_REFINED", 0.0)
    t = time.perf_counter()
    img, fold, info = refine.refined_adjoint(op, d, with_fold=True, wavelength_m=0.2, level=0.15, normalize="fold")
    wall = time.perf_counter() - t
    # every voxel migrated: the columns off the coarse ones by the same pass as the whole image (to the bit), the
    # coarse ones by the coarse pass (the same sums in another order)
    off = np.ones((60, 60), bool)
    off[::3, ::3] = False
    np.testing.assert_array_equal(img[off], whole[off])
    np.testing.assert_array_equal(fold[off], whole_fold[off])
    np.testing.assert_allclose(img[~off], whole[~off], rtol=0, atol=1e-5 * np.abs(whole).max())
    np.testing.assert_allclose(fold[~off], whole_fold[~off], rtol=0, atol=1e-5 * whole_fold.max())
    cimg = op.on_grid(Grid3D(0.0, 0.0, 0.02, 0.06, 0.06, 0.02, 21, 21, 30)).adjoint(d)
    np.testing.assert_array_equal(img[::3, ::3], cimg[:20, :20])
    alone, no_fold, _ = refine.refined_adjoint(op, d, with_fold=False, wavelength_m=0.2, level=0.15, normalize="fold")
    np.testing.assert_array_equal(alone, img)
    assert no_fold is None
    assert info["refined_fraction"] == 1.0 and info["marked_fraction"] == marked
    assert info["fine_fraction"] == pytest.approx(off.mean())  # the coarse columns left out of the fine pass
    assert info["why"] == f"the coarse pass marked {marked:.0%} of the voxels: every voxel migrated"
    assert set(info["seconds"]) == {"coarse", "mark", "fine", "fill"} and 0 <= sum(info["seconds"].values()) <= wall
    assert min(info["seconds"].values()) >= 0 and info["stride"] == 3


def _pipe_survey():
    walk = random_walk(5000, area=((0.0, 2.4), (0.0, 2.4)), step_m=0.02, turn_rate=0.1, seed=7)
    sc = ForwardScene(eps_r=9.0, conductivity_s_m=0.002, pipes=[Pipe((0.4, 0.9, -0.55), (2.0, 1.3, -0.55), 0.04),
                                                                Pipe((1.5, 0.3, -0.35), (1.5, 2.1, -0.35), 0.02)])
    data = forward_model(sc, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.1, frequency_hz=500e6,
                         n_samples=256, time_window_s=24e-9, air_wave=1.0, ground_wave=0.5)
    return Survey(data=data, dt_s=24e-9 / 256, positions_xyz=walk.positions_xyz,
                  orientations_quat_wxyz=walk.orientations_quat_wxyz, offset_m=0.1, frequency_hz=500e6, eps_r=9.0)


def test_reconstruct_coarse_to_fine_finds_the_same_targets_and_says_what_it_did(tmp_path, monkeypatch):
    import functools

    s = _pipe_survey()
    full = reconstruct(s, ReconstructConfig(coarse_to_fine=False))
    fast = reconstruct(s, ReconstructConfig())  # coarse-to-fine: the default
    assert full.refine is None and fast.grid == full.grid
    r = fast.refine
    assert r["stride"] == 3 and r["frequency_hz"] == 500e6 and 0 < r["refined_fraction"] < 0.3
    assert r["refine"] == "depth ranges" and r["refined_fraction"] < r["refined_columns"] < 0.7
    assert r["wavelength_m"] == pytest.approx(299792458.0 / 3 / 500e6)
    ref = np.percentile(full.envelope.max(axis=2), 99.5)
    near = full.envelope >= full.config["threshold"] * ref
    # depth ranges: the same targets within two voxels, the envelope where they are within 1 % of its peak (the
    # interpolated voxels beyond a range reach into its envelope a little: measured 0.23 % here, and a line's end,
    # where its ridge crosses the threshold, 1.0 cm and 2.0 cm off; two voxels, not one, so that rounding on another
    # CPU cannot push an end that moved by exactly one voxel over the bound)
    assert len(full.targets) == len(fast.targets) >= 2
    for a, b in zip(full.targets, fast.targets):
        assert a.kind == b.kind
        np.testing.assert_allclose(np.asarray(b.points_xyz), np.asarray(a.points_xyz), atol=2 * full.grid.dx)
        assert b.score == pytest.approx(a.score, abs=0.01)  # (measured 0.003)
    change = np.abs(fast.envelope - full.envelope)[near].max() / full.envelope.max()
    assert 0 < change < 0.01
    # whole columns: the same targets to float rounding (refined columns are migrated whole, the envelope theirs)
    monkeypatch.setattr(refine, "refined_adjoint", functools.partial(refine.refined_adjoint, depth_margin=None))
    whole = reconstruct(s, ReconstructConfig(coarse_to_fine=True))
    assert whole.refine["refine"] == "whole columns" and whole.refine["refined_fraction"] > r["refined_fraction"]
    assert len(full.targets) == len(whole.targets)
    for a, b in zip(full.targets, whole.targets):
        assert a.kind == b.kind
        np.testing.assert_allclose(np.asarray(b.points_xyz), np.asarray(a.points_xyz), atol=1e-4)
        assert b.score == pytest.approx(a.score, rel=1e-4)
    np.testing.assert_allclose(whole.envelope[near], full.envelope[near], rtol=0, atol=1e-5 * full.envelope.max())
    write_reconstruction(fast, tmp_path)
    doc = json.loads((tmp_path / "config.json").read_text())
    assert doc["refine"]["stride"] == 3 and doc["config"]["coarse_to_fine"] is True
    assert doc["refine"]["refine"] == "depth ranges" and doc["refine"]["depth_margin_wavelengths"] == 0.5


def test_a_profile_or_no_aperture_skips_the_coarse_pass_and_says_why():
    s = _pipe_survey()
    r = reconstruct(s, ReconstructConfig(coarse_to_fine=True, aperture_deg=None, max_depth_m=0.4, spacing_m=0.04))
    assert "no aperture" in r.refine["skipped"]


@pytest.mark.parametrize("level", [0.0, -0.1, 1.5, float("nan")])
def test_refine_level_out_of_range_is_named(level):
    with pytest.raises(InvalidDataError, match="refine_level must be"):
        check_config(ReconstructConfig(refine_level=level))
    with pytest.raises(InvalidDataError, match="coarse_to_fine must be true or false"):
        check_config(ReconstructConfig(coarse_to_fine="yes"))


def _small_survey(frequency_hz=600e6, zero=False, line=False):
    if line:  # one straight profile along x
        n = 120
        pos = np.c_[np.linspace(0.0, 1.2, n), np.full(n, 0.5), np.zeros(n)]
        quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    else:
        walk = random_walk(400, area=((0.0, 1.0), (0.0, 1.0)), step_m=0.02, turn_rate=0.1, seed=2)
        pos, quat = walk.positions_xyz, walk.orientations_quat_wxyz
    sc = ForwardScene(eps_r=6.0, spheres=[Sphere((0.5, 0.5, -0.3), 0.04)])
    data = forward_model(sc, pos, quat, offset_m=0.05, frequency_hz=600e6, n_samples=120, time_window_s=10e-9,
                         air_wave=1.0)
    if zero:
        data = np.zeros_like(data)
    return Survey(data=data, dt_s=10e-9 / 120, positions_xyz=pos, orientations_quat_wxyz=quat, offset_m=0.05,
                  frequency_hz=frequency_hz, eps_r=6.0)


def test_where_coarse_to_fine_cannot_gain_it_says_why_and_migrates_every_voxel():
    small = dict(coarse_to_fine=True, spacing_m=0.03, max_depth_m=0.4)
    s = _small_survey()
    cases = [
        (ReconstructConfig(**small, aperture_deg=None), s, "no aperture: every trace reaches every voxel"),
        (ReconstructConfig(**small, tile_m=0.6), s, "site tiles migrate every voxel"),
        (ReconstructConfig(**small, engine="numpy"), s, "engine 'numpy' migrates every voxel"),
        (ReconstructConfig(**small), _small_survey(frequency_hz=None, zero=True),
         "the traces carry no frequency to size the coarse pass by"),
    ]
    for cfg, survey, why in cases:
        if cfg.engine == "numpy":  # (the numpy engine is slow: a few traces, a small grid)
            survey = survey.replace(data=survey.data[:40], positions_xyz=survey.positions_xyz[:40],
                                    orientations_quat_wxyz=survey.orientations_quat_wxyz[:40])
        r = reconstruct(survey, cfg)
        assert r.refine == {"skipped": why}
    with pytest.warns(Warning, match="profile"):
        r = reconstruct(_small_survey(line=True), ReconstructConfig(**small))
    assert r.refine == {"skipped": "one profile, migrated in 2D"}
    # a narrower cone than 45 degrees still refines; the data's own frequency is reported beside the header's
    r = reconstruct(s, ReconstructConfig(coarse_to_fine=True, spacing_m=0.01, max_depth_m=0.4, aperture_deg=40))
    assert r.refine["stride"] >= 2 and r.refine["frequency_hz"] == pytest.approx(max(600e6, r.refine[
        "data_frequency_hz"])) and 3e8 < r.refine["data_frequency_hz"] < 1.2e9


def test_coarse_to_fine_marks_by_the_image_normalised_as_asked():
    s = _pipe_survey()
    refs = {}
    for how in ("sqrt_fold", "fold", "none"):
        r = reconstruct(s, ReconstructConfig(coarse_to_fine=True, normalize=how, max_depth_m=0.8))
        assert r.refine["stride"] == 3 and (r.fold is None) == (how == "none")
        refs[how] = r.refine["reference"]
    # the reference is the coarse envelope's, divided by the fold, its square root or nothing: three scales
    assert len({round(v, 12) for v in refs.values()}) == 3


def _sphere_op(n=600, size=40, nd=20):
    walk, data = _sphere_survey(n)
    tx, rx = antenna_positions(walk.positions_xyz, walk.orientations_quat_wxyz, 0.05)
    grid = Grid3D(0.4, 0.3, 0.02, 0.02, 0.02, 0.02, size, size, nd)
    op = BackProjection(grid, tx, rx, dt_s=12e-9 / 160, n_samples=160, eps_r=6.0, aperture_deg=45)
    return op, data.astype(np.float32)


def test_what_the_refined_pass_reports():
    op, d = _sphere_op(size=60)
    t = time.perf_counter()
    img, fold, info = refine.refined_adjoint(op, d, with_fold=False, wavelength_m=0.13, level=0.4,
                                             normalize="sqrt_fold")
    wall = time.perf_counter() - t
    assert fold is None and img.shape == op.grid.shape
    assert set(info) == {"stride", "coarse_grid", "coarse_trace_step", "wavelength_m", "level", "reference", "refine",
                         "depth_margin_wavelengths", "refined_fraction", "refined_columns", "fine_fraction",
                         "seconds"}
    assert info["stride"] == 2 and info["coarse_grid"] == [31, 31, 20] and info["wavelength_m"] == 0.13
    assert info["coarse_trace_step"] == 1  # (600 traces: every one)
    assert info["level"] == 0.4 and info["depth_margin_wavelengths"] == refine.DEPTH_MARGIN
    assert 0 < info["refined_fraction"] < info["refined_columns"] < 0.7 and info["refine"] == "depth ranges"
    assert set(info["seconds"]) == {"coarse", "mark", "fine", "fill"}
    assert all(0 <= v for v in info["seconds"].values()) and sum(info["seconds"].values()) <= wall
    whole = op.adjoint(d)
    same = np.abs(img - whole) <= 1e-5 * np.abs(whole).max()
    assert same.mean() >= info["refined_fraction"]  # the refined voxels (and the coarse columns) are the whole image's
    _, _, cinfo = refine.refined_adjoint(op, d, with_fold=False, wavelength_m=0.13, level=0.4, normalize="sqrt_fold",
                                         depth_margin=None)
    assert set(cinfo) == {"stride", "coarse_grid", "coarse_trace_step", "wavelength_m", "level", "reference", "refine",
                          "margin_coarse_columns", "refined_fraction", "refined_columns", "fine_fraction", "seconds"}
    assert cinfo["refine"] == "whole columns" and cinfo["margin_coarse_columns"] == 0
    assert cinfo["refined_fraction"] == cinfo["refined_columns"] == pytest.approx(info["refined_columns"])
    assert cinfo["reference"] == info["reference"] > 0
    # the reference's percentile is the one asked, in either mode; the fine pass migrates only the ranges
    calls = []
    adjoint = op.adjoint

    def spy(data, **kw):
        calls.append(kw.get("depth_range"))
        return adjoint(data, **kw)

    op.adjoint = spy
    for margin in (refine.DEPTH_MARGIN, None):
        calls.clear()
        low = refine.refined_adjoint(op, d, with_fold=False, wavelength_m=0.13, level=0.4, normalize="sqrt_fold",
                                     reference_percentile=98, depth_margin=margin)[2]
        assert 0 < low["reference"] < info["reference"] and low["refined_fraction"] > info["refined_fraction"] / 2
        # (the coarse pass's operator is a copy of this one, the spy with it: every depth of its columns)
        assert len(calls) == 2 and calls[0] is None and calls[1].shape == (60, 60, 2)
        kk = np.arange(op.grid.nd)
        fine = (kk >= calls[1][..., :1]) & (kk < calls[1][..., 1:])
        # every other column along x and y is a coarse one, migrated whole already: the fine pass leaves it out
        assert not fine[::2, ::2].any() and fine.mean() == pytest.approx(low["fine_fraction"])
        assert fine.mean() < low["refined_fraction"]


def test_too_few_columns_apart_migrates_every_voxel_and_says_so():
    op, d = _sphere_op(300, 20, 10)
    whole, whole_fold = op.adjoint(d, with_fold=True)
    for with_fold in (True, False):
        img, fold, info = refine.refined_adjoint(op, d, with_fold=with_fold, wavelength_m=0.08, level=0.15,
                                                 normalize="fold")  # a third of 8 cm: 1 column of 2 cm
        assert info == {"stride": 1, "refined_fraction": 1.0,
                        "why": "the grid's columns are within a third of a wavelength of each other already"}
        np.testing.assert_array_equal(img, whole)
        if with_fold:
            np.testing.assert_array_equal(fold, whole_fold)
        else:
            assert fold is None
