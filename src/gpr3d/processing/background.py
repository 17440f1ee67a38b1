"""DC and background removal."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

__all__ = ["moving_background", "remove_dc", "remove_background"]


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
    data: np.ndarray, *, method: str = "mean", window_traces: int | None = None, trailing: bool = False
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
        layers); the edges repeat. A centred window as long as the survey or longer: the whole survey's.
    trailing : bool
        With ``window_traces``: the window ends at each trace (the trace and the ``window_traces - 1`` before it;
        before the first trace the first repeats) instead of being centred on it: no trace after it is needed,
        what a survey processed as it is recorded can do without waiting.

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
    if window_traces is None or (window_traces >= x.shape[0] and not trailing):
        if method == "mean":
            bg = x.astype(np.float64).mean(axis=0, keepdims=True)
        else:
            bg = np.median(x, axis=0, keepdims=True)
    else:
        bg = moving_background(x, window_traces, method=method, trailing=trailing)
    return (x - bg).astype(np.float32)


def moving_background(data: np.ndarray, window_traces: int, *, method: str = "mean",
                      trailing: bool = False) -> np.ndarray:
    """Each trace's background over a moving window of traces, however few traces there are (the edges repeat).

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    window_traces : int
        Traces in the window (>= 2).
    method : {"mean", "median"}
        The background over the window.
    trailing : bool
        The window ends at each trace instead of being centred on it.

    Returns
    -------
    ndarray
        ``(n_traces, n_samples)``: float64 means, or medians in ``data``'s float32.

    Raises
    ------
    ValueError
        A window of fewer than two traces, or an unknown method.
    """
    w = int(window_traces)
    if w < 2:
        raise ValueError(f"window_traces must be >= 2, got {window_traces}")
    x = np.asarray(data, dtype=np.float32)
    shift = (w - 1) // 2 if trailing else 0  # scipy's origin: the window moved back to end at the trace
    if method == "mean":
        return uniform_filter1d(x.astype(np.float64), size=w, axis=0, mode="nearest", origin=shift)
    if method == "median":
        return median_filter(x, size=(w, 1), mode="nearest", origin=(shift, 0))
    raise ValueError(f"unknown background method {method!r} (use 'mean' or 'median')")
