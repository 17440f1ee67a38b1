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

The coarse pass also thins the traces where they lie closer along the antenna's path than a quarter of a
wavelength (:func:`coarse_trace_step`: every second trace of a cart triggering every 2 cm at 500 MHz in eps_r 9):
its image, of columns a third of a wavelength apart, needs no denser sampling (a quarter wavelength is the
aliasing limit of dips up to 90 degrees), and its sums and fold are scaled by the traces left out. The coarse
columns inside the refined ranges are then migrated again from every trace with the fine pass, so the refined
voxels are still what migrating every voxel gives. The thinned image's incoherent noise is sqrt(m) times
stronger: where it marks more than ``THIN_UP_TO`` of the voxels (a busy or noisy image, where it would mark more
than thinning saves), the coarse pass is completed with the other traces and marked again, as without thinning.
On the 8000-trace survey of ``benchmarks/bench_stages.py`` the migration took 0.98 s instead of 1.56 s, the
targets the same to 2 mm, the envelope where targets are within 0.5 % of its peak of every voxel's (off the
targets, within 10 %, 2.1 % at the 99th percentile, as without thinning); the 13 scenes of
``benchmarks/results/coarse_to_fine.md`` keep their targets, 29.8 s against 30.9 s without thinning (two thinned,
three noisy soils thinned and completed, within 3 % of their time without thinning).

What was done is returned as a dict for ``config.json`` (``"refine"``).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D

__all__ = ["coarse_stride", "coarse_trace_step", "dominant_frequency_hz", "refine_columns", "refine_ranges",
           "refined_adjoint"]

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
#: the coarse pass keeps every m-th trace so that the kept ones lie at most this many wavelengths apart along the path
TRACE_WAVELENGTHS = 1 / 4
#: the coarse pass keeps at least every this-many-th trace
MAX_TRACE_STEP = 4
#: surveys of fewer traces than this keep them all in the coarse pass (it is short; its image from a few hundred
#: traces would be noisier)
MIN_TRACES_TO_THIN = 2000
#: a thinned coarse pass that marks more than this share of the voxels is completed with the other traces (a busy or
#: noisy image, where the thinned pass's noise, sqrt(m) times stronger, would mark more than thinning saves)
THIN_UP_TO = 0.25


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


def coarse_trace_step(tx: np.ndarray, rx: np.ndarray, wavelength_m: float) -> int:
    """Every how many traces the coarse pass keeps: the median horizontal distance between consecutive traces'
    tx-rx midpoints (along the path, in recording order) into ``TRACE_WAVELENGTHS`` of ``wavelength_m``, at most
    ``MAX_TRACE_STEP``; 1 (every trace) for fewer than ``MIN_TRACES_TO_THIN`` traces."""
    n = len(tx)
    if n < MIN_TRACES_TO_THIN:
        return 1
    mid = 0.5 * (np.asarray(tx)[:, :2] + np.asarray(rx)[:, :2])
    step = float(np.median(np.hypot(*np.diff(mid, axis=0).T)))
    if not step > 0:  # a cart standing still: repeated traces add nothing the coarse image needs
        return MAX_TRACE_STEP
    return int(min(max(math.floor(TRACE_WAVELENGTHS * wavelength_m / step + 1e-9), 1), MAX_TRACE_STEP))


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


def _fill(coarse: np.ndarray, fine: np.ndarray, inside: np.ndarray, k: int, columns: bool) -> np.ndarray:
    """The fine image: ``fine`` where ``inside`` (the refined voxels), the ``coarse`` columns themselves on the fine
    grid's every ``k``-th column (``columns``: at every depth, the fine pass having left them out; otherwise the
    interpolation gives them outside the refined voxels), the coarse image interpolated across columns elsewhere."""
    nx, ny = fine.shape[:2]
    img = _interp(coarse, k, nx, ny)
    np.copyto(img, fine, where=inside)
    if columns:
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


def _mark(cimg, cfold, *, k, grid, level, wavelength_m, normalize, reference_percentile, depth_margin):
    """The ranges (``(nx, ny, 2)``) to refine from a coarse image and fold, and what :func:`refined_adjoint`
    reports of them."""
    from gpr3d.migration.masking import image_envelope
    from gpr3d.migration.reconstruct import normalise_by_fold

    norm = cimg if normalize == "none" else normalise_by_fold(cimg, cfold, normalize)[0]
    cenv = image_envelope(norm)
    if depth_margin is None:
        cols, ref, mc = refine_columns(cenv, k, grid, level=level, wavelength_m=wavelength_m,
                                       reference_percentile=reference_percentile)
        ranges = np.zeros((grid.nx, grid.ny, 2), np.int32)
        ranges[cols, 1] = grid.nd
        more = dict(reference=ref, refine="whole columns", margin_coarse_columns=mc)
    else:
        ranges, ref = refine_ranges(cenv, k, grid, level=level, wavelength_m=wavelength_m,
                                    margin_wavelengths=depth_margin, reference_percentile=reference_percentile)
        more = dict(reference=ref, refine="depth ranges", depth_margin_wavelengths=float(depth_margin))
    more.update(refined_fraction=float(_in_ranges(ranges, grid.nd).mean()),
                refined_columns=float((ranges[..., 1] > ranges[..., 0]).mean()))
    return ranges, more


def refined_adjoint(op, data, *, with_fold: bool, wavelength_m: float, level: float, normalize: str,
                    reference_percentile: float = 99.5, depth_margin: float | None = DEPTH_MARGIN,
                    trace_step: int | None = None):
    """The image (and fold) of ``op`` (a :class:`~gpr3d.migration.operator.BackProjection`) over ``data``, refined
    where the coarse envelope reaches ``level`` x its reference (see the module): each column's depth range with
    ``depth_margin`` wavelengths above and below (:func:`refine_ranges`), or whole columns (``depth_margin``
    None, :func:`refine_columns`). The coarse pass keeps every ``trace_step``-th trace (None:
    :func:`coarse_trace_step`'s). Returns ``(image, fold, info)``: ``fold`` None unless asked; ``info`` says what
    was done (``stride`` 1: everything migrated, no coarse pass)."""
    if trace_step is not None and (isinstance(trace_step, bool) or not isinstance(trace_step, (int, np.integer))
                                   or trace_step < 1):
        raise InvalidDataError(f"trace_step must be a whole number >= 1 (every how many traces the coarse pass "
                               f"reads) or None, got {trace_step!r}")
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
    m = coarse_trace_step(op.tx, op.rx, wavelength_m) if trace_step is None else int(trace_step)
    n = op.n_traces
    if m > 1:  # every m-th trace, the sums scaled by the traces left out
        part = np.arange(0, n, m)
        csum, fsum = cop.with_traces(part).adjoint(np.ascontiguousarray(data[part]), with_fold=True)
        scale = np.float32(n / len(part))
        cimg, cfold = csum * scale, fsum * scale
    else:
        cimg, cfold = cop.adjoint(data, with_fold=True)
    t_coarse = time.perf_counter() - t
    t = time.perf_counter()
    info = {"stride": k, "coarse_grid": [cgrid.nx, cgrid.ny, cgrid.nd], "coarse_trace_step": m,
            "wavelength_m": float(wavelength_m), "level": float(level)}
    mark = dict(k=k, grid=grid, level=level, wavelength_m=wavelength_m, normalize=normalize,
                reference_percentile=reference_percentile, depth_margin=depth_margin)
    ranges, more = _mark(cimg, cfold, **mark)
    fraction = more["refined_fraction"]
    t_mark = time.perf_counter() - t
    if m > 1 and fraction > THIN_UP_TO:
        # a busy (noisy) image: the thinned pass's stronger noise would mark more than it saves; the coarse pass is
        # completed with the other traces (the same sums as from every trace at once) and marked again
        t = time.perf_counter()
        rest = np.setdiff1d(np.arange(n), part)
        rimg, rfold = cop.with_traces(rest).adjoint(np.ascontiguousarray(data[rest]), with_fold=True)
        cimg, cfold = csum + rimg, fsum + rfold
        info.update(coarse_trace_step=1, thinned={"trace_step": m, "refined_fraction": fraction})
        m = 1
        t_coarse += time.perf_counter() - t
        t = time.perf_counter()
        ranges, more = _mark(cimg, cfold, **mark)
        fraction = more["refined_fraction"]
        t_mark += time.perf_counter() - t
    info.update(more)
    inside = _in_ranges(ranges, grid.nd)
    t = time.perf_counter()
    if fraction > MAX_REFINED:  # every voxel migrated: the other columns at every depth
        ranges[...] = (0, grid.nd)
        inside = np.ones(grid.shape, bool)
        info.update({"marked_fraction": fraction, "refined_fraction": 1.0,
                     "why": f"the coarse pass marked {fraction:.0%} of the voxels: every voxel migrated"})
    # the coarse columns are columns of the fine grid, migrated at every depth already: the fine pass leaves them
    # out (a 1 / stride**2 share of its work) and they keep the coarse pass's values (from every trace: m = 1)
    fine = ranges.copy()
    if m == 1:
        fine[::k, ::k] = 0
    info["fine_fraction"] = float(_in_ranges(fine, grid.nd).mean())
    out = op.adjoint(data, with_fold=with_fold, depth_range=fine)
    fimg, ffold = out if with_fold else (out, None)
    t_fine = time.perf_counter() - t
    t = time.perf_counter()
    img = _fill(cimg, fimg, inside, k, m == 1)
    fold = _fill(cfold, ffold, inside, k, m == 1) if with_fold else None
    info["seconds"] = {"coarse": t_coarse, "mark": t_mark, "fine": t_fine, "fill": time.perf_counter() - t}
    return img, fold, info
