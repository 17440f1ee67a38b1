"""Coarse-to-fine imaging: the back projection at full resolution only where the image holds energy.

A coarse pass migrates every ``stride``-th column of the grid (``stride`` from the wavelength: columns about a
third of a wavelength apart, which the focused image of a point spans several of), with the fold, normalised as
the image will be. Its envelope marks the voxels that reach ``level`` of the reference that target extraction
uses (the 99.5th percentile of the ridge map, :func:`gpr3d.migration.targets.extract_targets`), widened in depth
(:data:`DEPTH_MARGIN`) and across (:data:`LATERAL_MARGIN`); each column of the fine grid is then migrated over the depths its coarse
neighbours mark (one interval per column: :meth:`BackProjection.adjoint`'s ``depth_range``), and every other voxel
takes the coarse image interpolated across columns (the coarse columns are columns of the fine grid: there the
value is the migrated one at every depth). Where the fine pass ran, image and fold are what migrating every voxel
gives; the work is the coarse pass (about ``1 / stride**2``) plus the marked share (more than
:data:`MAX_REFINED` marked: every voxel is migrated instead).

What was done is returned as a dict for ``config.json`` (``"refine"``).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from gpr3d.core.grid import Grid3D

__all__ = ["coarse_stride", "dominant_frequency_hz", "refine_ranges", "refined_adjoint"]

#: the coarse columns' spacing, as a share of the wavelength in the ground
COARSE_WAVELENGTHS = 1 / 3
#: the coarse stride is at most this (the lateral interpolation of the rest stays short)
MAX_STRIDE = 4
#: how far the marked voxels are widened, in wavelengths: in depth (the envelope's Hilbert transform reaches along
#: the whole column: with half a wavelength, the interpolated rest moved borderline columns across the target
#: threshold and changed the targets of 2 scenes in 18; with two, none), and across (beyond the fine column's coarse
#: neighbours)
DEPTH_MARGIN = 2.0
LATERAL_MARGIN = 0.0
#: more than this share of the voxels marked: every voxel is migrated instead (a fine pass over many short depth
#: ranges costs about what the whole image does; measured in ``benchmarks/eval_coarse_to_fine.py``)
MAX_REFINED = 0.3


def dominant_frequency_hz(data: np.ndarray, dt_s: float) -> float:
    """The frequency where the traces' mean amplitude spectrum peaks (Hz; its DC bin left out)."""
    n = data.shape[1]
    step = max(1, data.shape[0] // 512)  # a few hundred traces tell the spectrum
    spec = np.abs(np.fft.rfft(np.asarray(data[::step], dtype=np.float64), axis=1)).mean(axis=0)
    spec[0] = 0.0
    return float(np.argmax(spec)) / (n * dt_s)


def coarse_stride(grid: Grid3D, wavelength_m: float) -> int:
    """Every how many columns the coarse pass migrates: a third of ``wavelength_m`` over the grid's column
    spacing, at most :data:`MAX_STRIDE`; 1 (nothing to gain) where the grid is that coarse already or too small."""
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


def _paste(dst: np.ndarray, src: np.ndarray, krange: np.ndarray) -> None:
    """``dst[i, j, lo:hi] = src[i, j, lo:hi]`` for each column's ``krange[i, j] = (lo, hi)``."""
    lo, hi = krange[..., 0], krange[..., 1]
    for a in np.unique(lo[hi > lo]):  # columns grouped by where their range starts: a few dozen slices
        sel = (lo == a) & (hi > lo)
        ii, jj = np.nonzero(sel)
        top = int(hi[sel].max())
        kk = np.arange(a, top)
        keep = kk[None, :] < hi[ii, jj][:, None]
        block = src[ii[:, None], jj[:, None], kk[None, :]]
        cur = dst[ii[:, None], jj[:, None], kk[None, :]]
        dst[ii[:, None], jj[:, None], kk[None, :]] = np.where(keep, block, cur)


def refine_ranges(cenv: np.ndarray, k: int, grid: Grid3D, *, level: float, wavelength_m: float,
                  reference_percentile: float = 99.5):
    """Each fine column's depths to migrate, ``(nx, ny, 2)`` int32 ``[lo, hi)`` (``hi = 0``: none), from the coarse
    envelope ``cenv`` (every ``k``-th column of ``grid``): the voxels where it reaches ``level`` x the
    ``reference_percentile`` of its ridge map (the column maxima), widened by :data:`DEPTH_MARGIN` wavelengths in
    depth and :data:`LATERAL_MARGIN` across; a fine column takes the union of its (up to) four coarse neighbours'
    depths, as one interval. Returns ``(ranges, reference, depth margin in voxels, lateral margin in coarse
    columns)``."""
    from scipy import ndimage

    ref = float(np.percentile(cenv.max(axis=2), reference_percentile))
    hot = cenv >= level * ref if ref > 0 else np.ones(cenv.shape, bool)
    md = int(math.ceil(DEPTH_MARGIN * wavelength_m / grid.dd - 1e-9))
    mc = int(math.ceil(LATERAL_MARGIN * wavelength_m / (k * max(grid.dx, grid.dy)) - 1e-9))
    nd = cenv.shape[2]
    any_d = hot.any(axis=2)
    first = np.where(any_d, np.argmax(hot, axis=2), nd)
    last = np.where(any_d, nd - 1 - np.argmax(hot[:, :, ::-1], axis=2), -1)
    if mc > 0:
        first = ndimage.minimum_filter(first, size=2 * mc + 1, mode="nearest")
        last = ndimage.maximum_filter(last, size=2 * mc + 1, mode="nearest")
    lo = np.clip(first - md, 0, nd)
    hi = np.where(last >= 0, np.clip(last + 1 + md, 0, nd), 0)
    ix = np.arange(grid.nx) // k
    iy = np.arange(grid.ny) // k
    ix1 = np.minimum(ix + 1, cenv.shape[0] - 1)
    iy1 = np.minimum(iy + 1, cenv.shape[1] - 1)
    pairs = [np.ix_(a, b) for a in (ix, ix1) for b in (iy, iy1)]
    flo = np.minimum.reduce([lo[p] for p in pairs])
    fhi = np.maximum.reduce([hi[p] for p in pairs])
    empty = fhi <= flo
    flo[empty] = 0
    fhi[empty] = 0
    return np.stack([flo, fhi], axis=-1).astype(np.int32), ref, md, mc


def refined_adjoint(op, data, *, with_fold: bool, wavelength_m: float, level: float, normalize: str,
                    reference_percentile: float = 99.5):
    """The image (and fold) of ``op`` (a :class:`~gpr3d.migration.operator.BackProjection`) over ``data``, refined
    where the coarse envelope reaches ``level`` x its reference (see the module). Returns ``(image, fold, info)``:
    ``fold`` None unless asked; ``info`` says what was done (``stride`` 1: everything migrated, no coarse pass)."""
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
    krange, ref, md, mc = refine_ranges(cenv, k, grid, level=level, wavelength_m=wavelength_m,
                                        reference_percentile=reference_percentile)
    t_mark = time.perf_counter() - t
    fraction = float(np.maximum(krange[..., 1] - krange[..., 0], 0).sum()) / grid.size
    info = {"stride": k, "coarse_grid": [cgrid.nx, cgrid.ny, cgrid.nd], "wavelength_m": float(wavelength_m),
            "level": float(level), "reference": ref, "margin_depth_voxels": md, "margin_coarse_columns": mc,
            "refined_fraction": fraction}
    t = time.perf_counter()
    if fraction > MAX_REFINED:
        out = op.adjoint(data, with_fold=with_fold)
        img, fold = out if with_fold else (out, None)
        info.update({"marked_fraction": fraction, "refined_fraction": 1.0,
                     "why": f"the coarse pass marked {fraction:.0%} of the voxels: every voxel migrated",
                     "seconds": {"coarse": t_coarse, "mark": t_mark, "fine": time.perf_counter() - t}})
        return img, fold, info
    out = op.adjoint(data, with_fold=with_fold, depth_range=krange)
    fimg, ffold = out if with_fold else (out, None)
    t_fine = time.perf_counter() - t
    t = time.perf_counter()
    img = _interp(cimg, k, grid.nx, grid.ny)
    _paste(img, fimg, krange)
    fold = None
    if with_fold:
        fold = _interp(cfold, k, grid.nx, grid.ny)
        _paste(fold, ffold, krange)
    info["seconds"] = {"coarse": t_coarse, "mark": t_mark, "fine": t_fine, "fill": time.perf_counter() - t}
    return img, fold, info
