"""Detection-masked migration: migrate only the data inside hyperbola boxes.

A box ``[trace_start, t_start_s, trace_end, t_end_s]`` (CONVENTIONS.md) keeps a
window of the recording-order B-scan; its edges are tapered with half-cosines
(``taper_traces`` traces, ``taper_s`` seconds) so the cut makes no artefacts.
What the mask removes, migrated alone, is the noise map.
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["box_mask", "check_boxes", "masked_migration", "image_envelope", "signal_to_clutter"]


def _taper_1d(n: int, lo: float, hi: float, width: float) -> np.ndarray:
    """1 inside [lo, hi], half-cosine down to 0 over ``width`` outside, 0 beyond."""
    i = np.arange(n, dtype=float)
    d = np.maximum(lo - i, 0) + np.maximum(i - hi, 0)
    if width <= 0:
        return (d == 0).astype(float)
    return 0.5 * (1 + np.cos(np.pi * np.minimum(d / width, 1.0)))  # (cos(pi) = -1: zero from d = width on)


def box_mask(n_traces: int, n_samples: int, dt_s: float, boxes, *, taper_traces: float = 3.0,
             taper_s: float | None = None) -> np.ndarray:
    """Mask ``(n_traces, n_samples)`` in [0, 1]: 1 inside any box, tapered edges, 0 elsewhere.

    A box is ``[trace_start, t_start_s, trace_end, t_end_s]`` (times after the first sample).
    """
    mask = np.zeros((n_traces, n_samples))
    tw = (taper_s / dt_s) if taper_s else 3.0
    for i0, t0, i1, t1 in check_boxes(boxes, n_traces, n_samples * dt_s):
        a = _taper_1d(n_traces, i0, i1, taper_traces)
        b = _taper_1d(n_samples, t0 / dt_s, t1 / dt_s, tw)
        # only the block where both tapers are non-zero: elsewhere the box's mask is exactly 0 and leaves the
        # maximum as it is (a whole-record outer product per box took seconds with a hundred boxes)
        ia, ib = np.flatnonzero(a), np.flatnonzero(b)
        if ia.size == 0 or ib.size == 0:
            continue
        rows, cols = slice(ia[0], ia[-1] + 1), slice(ib[0], ib[-1] + 1)
        np.maximum(mask[rows, cols], np.outer(a[rows], b[cols]), out=mask[rows, cols])
    return mask.astype(np.float32)


def check_boxes(boxes, n_traces: int, window_s: float) -> list[tuple[float, float, float, float]]:
    """The boxes as float tuples, or a one-line :class:`~gpr3d.core.errors.InvalidDataError` naming the first bad one."""
    return [_check_box(k, b, n_traces, window_s) for k, b in enumerate(boxes)]


def _check_box(k, b, n_traces, window_s):
    try:
        i0, t0, i1, t1 = (float(v) for v in b)
    except (TypeError, ValueError):
        raise InvalidDataError(f"box {k} must be 4 numbers [trace_start, t_start_s, trace_end, t_end_s], got {b!r}")
    if not all(np.isfinite([i0, t0, i1, t1])) or i1 < i0 or t1 <= t0:
        raise InvalidDataError(f"box {k} {b!r} is empty or not finite: need trace_start <= trace_end, t_start < t_end")
    if i1 < 0 or i0 > n_traces - 1 or t1 < 0 or t0 > window_s:
        raise InvalidDataError(f"box {k} {b!r} lies outside the data ({n_traces} traces, {window_s * 1e9:.4g} ns): "
                               "are its times in seconds?")
    return i0, t0, i1, t1


def masked_migration(op, data, mask):
    """``(image of data * mask, noise map = image of data * (1 - mask))`` through ``op.adjoint``."""
    data = np.asarray(data, dtype=np.float32)
    return op.adjoint(data * mask), op.adjoint(data * (1.0 - mask))


def image_envelope(image: np.ndarray, *, chunk_voxels: int = 4_000_000) -> np.ndarray:
    """Instantaneous amplitude of a migrated image along depth (Hilbert transform per column).

    Each column is followed by zeros to at least twice its length (:func:`~gpr3d.processing.analytic.fast_length`)
    before the transform, so that the bottom of a column does not wrap onto its top (the voxels below one reach it
    as the Hilbert transform's 1 / distance, not through the wrap): the shallow voxels' envelope hardly depends on
    how deep the grid goes. Works on slabs of about ``chunk_voxels`` voxels, so the complex temporaries stay small
    (a 1e8-voxel image needs its own size again, not the 16x of one whole transform).
    """
    # (the analytic signal on NumPy's FFT, as scipy.signal.hilbert makes it: scipy.signal, with the scipy.stats it
    # pulls in, takes longer to import than a whole reconstruction's envelope takes)
    from gpr3d.processing.analytic import fast_length, hilbert_envelope

    img = np.asarray(image, dtype=np.float32)
    out = np.empty_like(img)
    n = fast_length(2 * img.shape[2])
    step = max(1, chunk_voxels // max(img.shape[1] * n, 1))
    for i in range(0, img.shape[0], step):
        out[i : i + step] = hilbert_envelope(img[i : i + step], axis=2, n=n)
    return out


def signal_to_clutter(envelope: np.ndarray, target_mask: np.ndarray) -> float:
    """Signal-to-clutter ratio (dB) of an image envelope.

    ``20 log10(mean envelope on the true targets / RMS envelope elsewhere)``, with
    ``target_mask`` marking the voxels within a tolerance of the true targets.
    """
    sig = float(np.mean(envelope[target_mask]))
    clut = float(np.sqrt(np.mean(envelope[~target_mask] ** 2)))
    return 20 * np.log10(sig / clut) if clut > 0 else float("inf")
