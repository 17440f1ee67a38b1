"""B-scans as images: the rendering that datasets, networks and figures share.

:func:`bscan_image` is the 'hot' colour rendering of a whole record (the reference
paper's labelling images, and ``image.png`` of every simulated sample);
:func:`network_view` is the processing every network sees (dewow, mean trace removed,
rows resampled and equalised) and :func:`render_channels` its 3-channel image
(the detector's windows, DepthNet's); :func:`normalise_window` scales a block.
"""

from __future__ import annotations

import numpy as np
from gpr3d.core.errors import InvalidDataError
from gpr3d.processing.analytic import hilbert_envelope, running_mean

__all__ = ["bscan_image", "resample_rows", "normalise_window", "hot_rgb", "network_view", "equalise_rows",
           "render_channels", "record_scale"]


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
    """RGB uint8 image ``(height, n_traces, 3)``: 'hot' colour map of the absolute background-removed data."""
    x = survey.remove_background().data
    img = np.abs(resample_rows(x, height).T)  # (height, n_traces)
    scale = np.percentile(img, 99.5) or 1.0
    return hot_rgb(img / scale)


def network_view(survey, rows: int, *, dewow: bool = True, background: bool = True,
                 equalise: bool = True) -> np.ndarray:
    """Processed data ``(n_traces, rows)`` float32 of a record, as the networks see it.

    Dewow (a running mean over about one antenna period removed), the mean trace
    removed, the whole time window resampled to ``rows`` rows (anti-aliased), each row
    divided by its RMS across the record (deep echoes as bright as shallow). Time zero
    does not move: row ``r`` is the time ``r * T / (rows - 1)`` from the first sample.
    """
    data = np.asarray(survey.data, dtype=np.float64)
    if not np.all(np.isfinite(data)):
        raise InvalidDataError("the record holds NaN/inf samples; detection needs finite data")
    if data.shape[0] < 2 or data.shape[1] < 8:
        raise InvalidDataError(f"a {data.shape[0]} x {data.shape[1]} record is too small to detect in")
    if dewow:
        # remove the low-frequency wow: a running mean over about one period of the antenna
        f = survey.frequency_hz or 1.0 / (data.shape[1] * survey.dt_s / 20)
        w = int(np.clip(round(1.0 / (f * survey.dt_s)), 3, data.shape[1] // 2 | 1))
        data = data - running_mean(data, w, axis=1)
    if background:
        data = data - data.mean(axis=0, keepdims=True)
    factor = data.shape[1] / rows
    if factor > 1.5:  # anti-alias before the time axis shrinks
        data = running_mean(data, int(round(factor)), axis=1)
    out = resample_rows(data.astype(np.float32), rows)  # (float32, an array of its own)
    return equalise_rows(out) if equalise else out


def equalise_rows(view: np.ndarray) -> np.ndarray:
    """``view`` ``(n_traces, rows)`` with each row divided by its RMS across the traces (smoothed over ``rows / 16``
    rows, and at least 5 % of the largest): :func:`network_view`'s last step, float32. ``network_view(s, rows)``
    is ``equalise_rows(network_view(s, rows, equalise=False))``, to the bit."""
    out = np.asarray(view, dtype=np.float64)
    rows = out.shape[1]
    rms = np.sqrt(np.mean(out**2, axis=0))
    rms = running_mean(rms, max(3, rows // 16))
    floor = 0.05 * float(np.max(rms)) if rms.size else 0.0
    return (out / np.maximum(rms, floor if floor > 0 else 1.0)).astype(np.float32)


def render_channels(block: np.ndarray, style: str = "channels", *, scale: float | None = None) -> np.ndarray:
    """Image ``(3, rows, cols)`` float32 in [0, 1] of a processed block ``(cols traces, rows)``."""
    x = normalise_window(np.asarray(block, dtype=np.float32).T, scale=scale)  # (rows, cols) in [-1, 1]
    env = hilbert_envelope(x, axis=0).astype(np.float32)
    if style == "hot":
        return np.ascontiguousarray(hot_rgb(np.clip(env, 0, 1)).transpose(2, 0, 1).astype(np.float32) / 255.0)
    rows = x.shape[0]
    tg = x * np.linspace(0.5, 1.5, rows, dtype=np.float32)[:, None]
    return np.stack([0.5 + 0.5 * x, np.clip(env, 0, 1), 0.5 + 0.5 * np.clip(tg, -1, 1)]).astype(np.float32)


def record_scale(processed: np.ndarray) -> float:
    """The amplitude that every window of one record is normalised by (99.5th percentile of the absolute data)."""
    return float(np.percentile(np.abs(processed), 99.5)) or 1.0
