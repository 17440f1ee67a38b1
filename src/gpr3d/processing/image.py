"""B-scans as images: the rendering that datasets, detectors and figures share.

:func:`bscan_image` is the 'hot' colour rendering of a whole record (the reference
paper's labelling images, and ``image.png`` of every simulated sample);
:func:`normalise_window` turns a block of traces into the detector's input.
"""

from __future__ import annotations

import numpy as np

__all__ = ["bscan_image", "resample_rows", "normalise_window", "hot_rgb"]


def resample_rows(data: np.ndarray, n_out: int) -> np.ndarray:
    """``(n_traces, n_samples)`` -> ``(n_traces, n_out)`` by linear interpolation in time (ends kept)."""
    data = np.asarray(data, dtype=np.float32)
    n_in = data.shape[1]
    if n_in == n_out:
        return data.copy()
    pos = np.linspace(0.0, n_in - 1.0, n_out)
    i0 = np.minimum(np.floor(pos).astype(np.int64), n_in - 2)
    w = (pos - i0).astype(np.float32)
    return data[:, i0] * (1 - w) + data[:, i0 + 1] * w


def hot_rgb(x: np.ndarray) -> np.ndarray:
    """Values in [0, 1] -> RGB uint8 through matplotlib's 'hot' colour map."""
    import matplotlib

    rgba = matplotlib.colormaps["hot"](np.clip(x, 0, 1))
    return (rgba[..., :3] * 255).astype(np.uint8)


def normalise_window(block: np.ndarray, *, clip_percentile: float = 99.5, scale: float | None = None) -> np.ndarray:
    """Signed block ``(rows, cols)`` -> float32 in [-1, 1]: divided by a robust amplitude, clipped.

    ``scale`` (if given) replaces the block's own ``clip_percentile`` of ``|block|``,
    so that windows of one record can share one scale.
    """
    block = np.asarray(block, dtype=np.float32)
    if scale is None:
        scale = float(np.percentile(np.abs(block), clip_percentile)) if block.size else 0.0
    if not np.isfinite(scale) or scale <= 0:
        return np.zeros_like(block)
    return np.clip(block / scale, -1.0, 1.0)


def bscan_image(survey, height: int) -> np.ndarray:
    """RGB uint8 image ``(height, n_traces, 3)``: 'hot' colour map of |background-removed data|."""
    x = survey.remove_background().data
    img = np.abs(resample_rows(x, height).T)  # (height, n_traces)
    scale = np.percentile(img, 99.5) or 1.0
    return hot_rgb(img / scale)
