"""Coarse-to-fine imaging: the back projection at full resolution only in the columns where the image holds energy.

A coarse pass migrates every ``stride``-th column of the grid (``stride`` from the wavelength: columns about a
third of a wavelength apart, which the focused image of a point spans several of), with the fold, normalised as
the image will be. Its envelope marks the coarse columns that reach ``level`` of the reference that target
extraction uses somewhere in depth (the 99.5th percentile of the ridge map,
:func:`gpr3d.migration.targets.extract_targets`), widened across by ``LATERAL_MARGIN``; every fine column next
to a marked coarse one (its two neighbours along x and y) is then migrated whole, at every depth
(:meth:`~gpr3d.migration.operator.BackProjection.adjoint`'s ``depth_range``), and every other column takes the
coarse image interpolated across columns (the coarse columns are columns of the fine grid: there the value is the migrated one).

Whole columns, because an envelope is a Hilbert transform along the column: refining only the marked depths left
the rest of the column interpolated, and that reached into the refined voxels' envelope enough to move
borderline columns across the target threshold (2 scenes in 18 changed their targets); whole columns changed
none (``benchmarks/results/coarse_to_fine.md``). In a refined column image, envelope and fold are what
migrating every voxel gives; the work is the coarse pass (about ``1 / stride**2``) plus the refined columns' share
(more than ``MAX_REFINED`` of the columns marked: every voxel is migrated instead).

What was done is returned as a dict for ``config.json`` (``"refine"``).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from gpr3d.core.grid import Grid3D

__all__ = ["coarse_stride", "dominant_frequency_hz", "refine_columns", "refined_adjoint"]

#: the coarse columns' spacing, as a share of the wavelength in the ground
COARSE_WAVELENGTHS = 1 / 3
#: the coarse stride is at most this (the lateral interpolation of the rest stays short)
MAX_STRIDE = 4
#: how far the marked coarse columns are widened, in wavelengths (beyond the fine columns' coarse neighbours)
LATERAL_MARGIN = 0.0
#: more than this share of the columns marked: every voxel is migrated instead (the refined columns cost their
#: share of the whole image's time, the coarse pass a tenth more: measured in ``benchmarks/eval_coarse_to_fine.py``)
MAX_REFINED = 0.7


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


def refined_adjoint(op, data, *, with_fold: bool, wavelength_m: float, level: float, normalize: str,
                    reference_percentile: float = 99.5):
    """The image (and fold) of ``op`` (a :class:`~gpr3d.migration.operator.BackProjection`) over ``data``, refined
    in the columns where the coarse envelope reaches ``level`` x its reference (see the module). Returns ``(image, fold, info)``:
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
    cols, ref, mc = refine_columns(cenv, k, grid, level=level, wavelength_m=wavelength_m,
                                   reference_percentile=reference_percentile)
    krange = np.zeros((grid.nx, grid.ny, 2), np.int32)
    krange[cols, 1] = grid.nd
    t_mark = time.perf_counter() - t
    fraction = float(cols.mean())
    info = {"stride": k, "coarse_grid": [cgrid.nx, cgrid.ny, cgrid.nd], "wavelength_m": float(wavelength_m),
            "level": float(level), "reference": ref, "margin_coarse_columns": mc, "refined_fraction": fraction}
    t = time.perf_counter()
    if fraction > MAX_REFINED:
        out = op.adjoint(data, with_fold=with_fold)
        img, fold = out if with_fold else (out, None)
        info.update({"marked_fraction": fraction, "refined_fraction": 1.0,
                     "why": f"the coarse pass marked {fraction:.0%} of the columns: every voxel migrated",
                     "seconds": {"coarse": t_coarse, "mark": t_mark, "fine": time.perf_counter() - t}})
        return img, fold, info
    out = op.adjoint(data, with_fold=with_fold, depth_range=krange)
    fimg, ffold = out if with_fold else (out, None)
    t_fine = time.perf_counter() - t
    t = time.perf_counter()
    img = _interp(cimg, k, grid.nx, grid.ny)
    img[cols] = fimg[cols]
    fold = None
    if with_fold:
        fold = _interp(cfold, k, grid.nx, grid.ny)
        fold[cols] = ffold[cols]
    info["seconds"] = {"coarse": t_coarse, "mark": t_mark, "fine": t_fine, "fill": time.perf_counter() - t}
    return img, fold, info
