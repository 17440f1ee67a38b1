"""Dewow: remove the slowly decaying 'wow' that rides under each trace."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

__all__ = ["dewow"]


def dewow(data: np.ndarray, dt_s: float, window_s: float) -> np.ndarray:
    """Subtract a centred running mean of length ``window_s`` (s) from every trace.

    A window of about one period of the antenna's centre frequency removes the wow and keeps the reflections. Near
    the trace ends the window is padded by repeating the edge sample.

    Parameters
    ----------
    data, dt_s : (n_traces, n_samples) array, float
        The B-scan and its sample interval (s).
    window_s : float
        Window length (s); rounded to an odd number of samples >= 3.

    Returns
    -------
    ndarray
        The dewowed traces, float32, as ``data``.

    Raises
    ------
    ValueError
        A window shorter than two samples.
    """
    n = int(round(window_s / dt_s))
    if n < 2:
        raise ValueError(f"dewow window {window_s:g} s is shorter than two samples ({dt_s:g} s)")
    n = n + 1 if n % 2 == 0 else n
    x = np.asarray(data, dtype=np.float32)
    trend = uniform_filter1d(x.astype(np.float64), size=n, axis=1, mode="nearest")
    return (x - trend).astype(np.float32)
