"""DC and background removal."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

__all__ = ["remove_dc", "remove_background"]


def remove_dc(data: np.ndarray, *, sample_range: tuple[int, int] | None = None) -> np.ndarray:
    """Subtract each trace's mean (over all samples, or over ``sample_range``).

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    sample_range : tuple of (int, int), optional
        ``(start, stop)``: the samples the mean is taken over (e.g. the pre-trigger samples).

    Returns
    -------
    ndarray
        The traces less their means, float32, as ``data``.

    Raises
    ------
    ValueError
        A range that selects no samples.
    """
    x = np.asarray(data, dtype=np.float32)
    part = x if sample_range is None else x[:, slice(*sample_range)]
    if part.shape[1] == 0:
        raise ValueError(f"sample_range {sample_range} selects no samples")
    return (x - part.astype(np.float64).mean(axis=1, keepdims=True)).astype(np.float32)


def remove_background(
    data: np.ndarray, *, method: str = "mean", window_traces: int | None = None
) -> np.ndarray:
    """Subtract the background trace: horizontal bands (antenna ringing, direct wave).

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    method : {"mean", "median"}
        The background over traces.
    window_traces : int, optional
        A centred moving window of that many traces (>= 2) instead of the whole survey (keeps slowly varying
        layers); the edges repeat.

    Returns
    -------
    ndarray
        The traces less the background trace, float32, as ``data``.

    Raises
    ------
    ValueError
        An unknown method, or a window of fewer than two traces.
    """
    x = np.asarray(data, dtype=np.float32)
    if method not in ("mean", "median"):
        raise ValueError(f"unknown background method {method!r} (use 'mean' or 'median')")
    if window_traces is None or window_traces >= x.shape[0]:
        if method == "mean":
            bg = x.astype(np.float64).mean(axis=0, keepdims=True)
        else:
            bg = np.median(x, axis=0, keepdims=True)
    else:
        w = int(window_traces)
        if w < 2:
            raise ValueError(f"window_traces must be >= 2, got {window_traces}")
        if method == "mean":
            bg = uniform_filter1d(x.astype(np.float64), size=w, axis=0, mode="nearest")
        else:
            bg = median_filter(x, size=(w, 1), mode="nearest")
    return (x - bg).astype(np.float32)
