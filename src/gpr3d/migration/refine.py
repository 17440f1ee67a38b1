"""Coarse-to-fine imaging: the back projection at full resolution only where the image holds energy.

A coarse pass migrates every ``stride``-th column of the grid (``stride`` from the wavelength: columns about a
third of a wavelength apart, which the focused image of a point spans several of), at every depth, with the fold,
normalised as the image will be. Its envelope marks the coarse voxels that reach ``level`` of the reference that
target extraction uses (the 99.5th percentile of the ridge map, :func:`gpr3d.migration.targets.extract_targets`).
Each fine column next to a marked coarse one (its two neighbours along x and y) is then migrated over one depth
range (:meth:`~gpr3d.migration.operator.BackProjection.adjoint`'s ``depth_range``): from the shallowest to the
deepest voxel its coarse neighbours marked, ``DEPTH_MARGIN`` wavelengths wider at both ends
(:func:`refine_ranges`). Every other voxel takes the coarse image interpolated across columns (the coarse columns
are columns of the fine grid: there the value is the migrated one). In the refined voxels image and fold are what
migrating every voxel gives (to rounding: the coarse columns, which the fine pass leaves out, keep the coarse
pass's sums); the work is the coarse pass (about ``1 / stride**2``) plus the refined voxels' off the coarse columns
(more than ``MAX_REFINED`` of the voxels marked: every voxel off the coarse columns is migrated instead).

The envelope is a Hilbert transform along each column, so the interpolated voxels beyond a refined range still
reach into its envelope a little: on the 13 scenes of ``benchmarks/results/coarse_to_fine.md`` the envelope where
targets are moved by at most 1 % of its peak and the targets by millimetres (the same completeness and false
targets overall), for 0.67 of the time of migrating every voxel (0.26 on a clean survey; 0.78 to 1.02 on noisy
soil, where the coarse pass marks deep noise): ``reconstruct``'s default. Refining whole columns instead
(``depth_margin=None``, :func:`refine_columns`, a marked coarse column's neighbours at every depth) keeps the
targets to the millimetre and saved nothing overall.

What was done is returned as a dict for ``config.json`` (``"refine"``).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from gpr3d.core.grid import Grid3D

__all__ = ["coarse_stride", "dominant_frequency_hz", "refine_columns", "refine_ranges", "refined_adjoint"]

#: the coarse columns' spacing, as a share of the wavelength in the ground
COARSE_WAVELENGTHS = 1 / 3
#: the coarse stride is at most this (the lateral interpolation of the rest stays short)
MAX_STRIDE = 4
#: how far the marked coarse columns are widened, in wavelengths (beyond the fine columns' coarse neighbours)
LATERAL_MARGIN = 0.0
#: more than this share of the voxels marked: every voxel off the coarse columns is migrated instead (the refined
#: voxels cost at least their share of the whole image's time: ``benchmarks/eval_coarse_to_fine.py``)
MAX_REFINED = 0.7
#: how far each column's refined depth range reaches above its shallowest and below its deepest marked voxel, in
#: wavelengths (the envelope's Hilbert transform spans the column: the interpolated voxels beyond the range reach
#: into it less the further away they are; 0.5 and 1 measured alike, ``benchmarks/results/coarse_to_fine.md``)
DEPTH_MARGIN = 0.5


def dominant_frequency_hz(data: np.ndarray, dt_s: float) -> float:
    """The frequency where the traces' mean amplitude spectrum peaks (Hz; its DC bin left out)."""
    n = data.shape[1]
    step = max(1, data.shape[0] // 512)  # a few hundred traces tell the spectrum
    spec = np.abs(np.fft.rfft(np.asarray(data[::step], dtype=np.float64), axis=1)).mean(axis=0)
    spec[0] = 0.0
    return float(np.argmax(spec)) / (n * dt_s)


def coarse_stride(grid: Grid3D, wavelength_m: float) -> int:
    """Every how many columns the coarse pass migrates: a third of ``wavelength_m`` over the grid's column
    spacing, at most ``MAX_STRIDE``; 1 (nothing to gain) where the grid is that coarse already or too small."""
    k = int(math.floor(COARSE_WAVELENGTHS * wavelength_m / max(grid.dx, grid.dy) + 1e-9))
    k = min(max(k, 1), MAX_STRIDE)
    return k if min(grid.nx, grid.ny) >= 4 * k else 1


def _coarse_grid(grid: Grid3D, k: int) -> Grid3D:
    # every k-th column from the first; one more where the last fine column lies past the last coarse one
    return replace(grid, dx=grid.dx * k, dy=grid.dy * k, nx=-(-(grid.nx - 1) // k) + 1, ny=-(-(grid.ny - 1) // k) + 1)


def _upsample(c: np.ndarray, k: int, n: int, axis: int) -> np.ndarray:
    """Linear interpolation of ``c`` (columns every ``k`` along ``axis``, the first at 0) onto ``n`` columns."""
    i = np.arange(n)
    if c.shape[axis] == 1:
        return np.take(c, np.zeros(n, int), axis=axis)
    i0 = np.minimum(i // k, c.shape[axis] - 2)
    shape = [1] * c.ndim
    shape[axis] = n
    w = ((i - i0 * k) / k).astype(c.dtype).reshape(shape)
    a = np.take(c, i0, axis=axis)
    b = np.take(c, i0 + 1, axis=axis)
    np.subtract(b, a, out=b)
    b *= w
    a += b
    return a


def _interp(c: np.ndarray, k: int, nx: int, ny: int) -> np.ndarray:
    """``c`` on every ``k``-th column of an ``nx`` x ``ny`` grid, interpolated (bilinear) to all its columns."""
    return _upsample(_upsample(c, k, nx, 0), k, ny, 1)


def _in_ranges(ranges: np.ndarray, nd: int) -> np.ndarray:
    """The voxels (``(nx, ny, nd)`` booleans) inside each column's depth range ``[first, end)`` of ``ranges``."""
    k = np.arange(nd)
    return (k >= ranges[..., :1]) & (k < ranges[..., 1:])


def _fill(coarse: np.ndarray, fine: np.ndarray, inside: np.ndarray, k: int) -> np.ndarray:
    """The fine image: ``fine`` where ``inside`` (the refined voxels), the ``coarse`` columns themselves on the fine
    grid's every ``k``-th column, the coarse image interpolated across columns elsewhere."""
    nx, ny = fine.shape[:2]
    img = _interp(coarse, k, nx, ny)
    np.copyto(img, fine, where=inside)
    img[::k, ::k] = coarse[: -(-nx // k), : -(-ny // k)]
    return img


def refine_columns(cenv: np.ndarray, k: int, grid: Grid3D, *, level: float, wavelength_m: float,
                   reference_percentile: float = 99.5):
    """The fine columns to migrate whole, ``(nx, ny)`` booleans, from the coarse envelope ``cenv`` (every ``k``-th
    column of ``grid``): the coarse columns where it reaches ``level`` x the ``reference_percentile`` of its ridge
    map (the column maxima) at some depth, widened by ``LATERAL_MARGIN`` wavelengths; a fine column is refined
    when either of its coarse neighbours along x (``i // k``, ``i // k + 1``) and along y is marked. Returns
    ``(columns, reference, lateral margin in coarse columns)``."""
    from scipy import ndimage

    ridge = cenv.max(axis=2)
    ref = float(np.percentile(ridge, reference_percentile))
    hot = ridge >= level * ref if ref > 0 else np.ones(ridge.shape, bool)
    mc = int(math.ceil(LATERAL_MARGIN * wavelength_m / (k * max(grid.dx, grid.dy)) - 1e-9))
    if mc > 0:
        hot = ndimage.binary_dilation(hot, structure=np.ones((2 * mc + 1, 2 * mc + 1), bool))
    ix = np.arange(grid.nx) // k
    iy = np.arange(grid.ny) // k
    ix1 = np.minimum(ix + 1, cenv.shape[0] - 1)
    iy1 = np.minimum(iy + 1, cenv.shape[1] - 1)
    cols = np.zeros((grid.nx, grid.ny), bool)
    for a in (ix, ix1):
        for b in (iy, iy1):
            cols |= hot[np.ix_(a, b)]
    return cols, ref, mc


def refine_ranges(cenv: np.ndarray, k: int, grid: Grid3D, *, level: float, wavelength_m: float,
                  margin_wavelengths: float, reference_percentile: float = 99.5):
    """The fine voxels to migrate, as one depth range per column (``(nx, ny, 2)`` int32, ``[first, end)``; empty
    where ``first >= end``), from the coarse envelope ``cenv`` (every ``k``-th column of ``grid``, every depth):
    in each coarse column, the depths where it reaches ``level`` x the ``reference_percentile`` of its ridge map,
    from the shallowest to the deepest, widened by ``margin_wavelengths`` of ``wavelength_m`` above and below; a
    fine column takes the union (shallowest to deepest) of its coarse neighbours' ranges (``i // k``,
    ``i // k + 1`` along x and y; ``LATERAL_MARGIN``, the whole-column marking's, does not apply). Returns
    ``(ranges, reference)``."""
    ridge = cenv.max(axis=2)
    ref = float(np.percentile(ridge, reference_percentile))
    hot = cenv >= level * ref if ref > 0 else np.ones(cenv.shape, bool)
    nd = cenv.shape[2]
    md = int(math.ceil(margin_wavelengths * wavelength_m / grid.dd - 1e-9))
    any_hot = hot.any(axis=2)
    first = np.where(any_hot, np.argmax(hot, axis=2) - md, nd)
    end = np.where(any_hot, nd - np.argmax(hot[:, :, ::-1], axis=2) + md, 0)
    ix = np.arange(grid.nx) // k
    iy = np.arange(grid.ny) // k
    ix1 = np.minimum(ix + 1, cenv.shape[0] - 1)
    iy1 = np.minimum(iy + 1, cenv.shape[1] - 1)
    lo = np.full((grid.nx, grid.ny), nd, np.int64)
    hi = np.zeros((grid.nx, grid.ny), np.int64)
    for a in (ix, ix1):
        for b in (iy, iy1):
            lo = np.minimum(lo, first[np.ix_(a, b)])
            hi = np.maximum(hi, end[np.ix_(a, b)])
    ranges = np.zeros((grid.nx, grid.ny, 2), np.int32)
    ranges[..., 0] = np.clip(lo, 0, nd)
    ranges[..., 1] = np.clip(hi, 0, nd)
    ranges[ranges[..., 0] >= ranges[..., 1]] = 0
    return ranges, ref


def refined_adjoint(op, data, *, with_fold: bool, wavelength_m: float, level: float, normalize: str,
                    reference_percentile: float = 99.5, depth_margin: float | None = DEPTH_MARGIN):
    """The image (and fold) of ``op`` (a :class:`~gpr3d.migration.operator.BackProjection`) over ``data``, refined
    where the coarse envelope reaches ``level`` x its reference (see the module): each column's depth range with
    ``depth_margin`` wavelengths above and below (:func:`refine_ranges`), or whole columns (``depth_margin``
    None, :func:`refine_columns`). Returns ``(image, fold, info)``: ``fold`` None unless asked; ``info`` says
    what was done (``stride`` 1: everything migrated, no coarse pass)."""
    from gpr3d.migration.masking import image_envelope
    from gpr3d.migration.reconstruct import normalise_by_fold

    grid = op.grid
    k = coarse_stride(grid, wavelength_m)
    if k < 2:
        out = op.adjoint(data, with_fold=with_fold)
        img, fold = out if with_fold else (out, None)
        return img, fold, {"stride": 1, "refined_fraction": 1.0,
                           "why": "the grid's columns are within a third of a wavelength of each other already"}
    t = time.perf_counter()
    cgrid = _coarse_grid(grid, k)
    cop = op.on_grid(cgrid)
    cimg, cfold = cop.adjoint(data, with_fold=True)
    norm = cimg if normalize == "none" else normalise_by_fold(cimg, cfold, normalize)[0]
    cenv = image_envelope(norm)
    t_coarse = time.perf_counter() - t
    t = time.perf_counter()
    info = {"stride": k, "coarse_grid": [cgrid.nx, cgrid.ny, cgrid.nd], "wavelength_m": float(wavelength_m),
            "level": float(level)}
    if depth_margin is None:
        cols, ref, mc = refine_columns(cenv, k, grid, level=level, wavelength_m=wavelength_m,
                                       reference_percentile=reference_percentile)
        ranges = np.zeros((grid.nx, grid.ny, 2), np.int32)
        ranges[cols, 1] = grid.nd
        info.update(reference=ref, refine="whole columns", margin_coarse_columns=mc)
    else:
        ranges, ref = refine_ranges(cenv, k, grid, level=level, wavelength_m=wavelength_m,
                                    margin_wavelengths=depth_margin, reference_percentile=reference_percentile)
        info.update(reference=ref, refine="depth ranges", depth_margin_wavelengths=float(depth_margin))
    inside = _in_ranges(ranges, grid.nd)
    fraction = float(inside.mean())
    info.update(refined_fraction=fraction, refined_columns=float((ranges[..., 1] > ranges[..., 0]).mean()))
    t_mark = time.perf_counter() - t
    t = time.perf_counter()
    if fraction > MAX_REFINED:  # every voxel migrated: the other columns at every depth
        ranges[...] = (0, grid.nd)
        inside = np.ones(grid.shape, bool)
        info.update({"marked_fraction": fraction, "refined_fraction": 1.0,
                     "why": f"the coarse pass marked {fraction:.0%} of the voxels: every voxel migrated"})
    # the coarse columns are columns of the fine grid, migrated at every depth already: the fine pass leaves them
    # out (a 1 / stride**2 share of its work) and they keep the coarse pass's values
    fine = ranges.copy()
    fine[::k, ::k] = 0
    info["fine_fraction"] = float(_in_ranges(fine, grid.nd).mean())
    out = op.adjoint(data, with_fold=with_fold, depth_range=fine)
    fimg, ffold = out if with_fold else (out, None)
    t_fine = time.perf_counter() - t
    t = time.perf_counter()
    img = _fill(cimg, fimg, inside, k)
    fold = _fill(cfold, ffold, inside, k) if with_fold else None
    info["seconds"] = {"coarse": t_coarse, "mark": t_mark, "fine": t_fine, "fill": time.perf_counter() - t}
    return img, fold, info
