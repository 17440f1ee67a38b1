"""Picking: the time and amplitude of an event near a guess."""

from __future__ import annotations

import numpy as np

__all__ = ["pick_peak"]


def pick_peak(data: np.ndarray, dt_s: float, trace: int, t_guess_s: float, half_window_s: float):
    """Largest value of ``data[trace]`` within ``t_guess_s +- half_window_s`` (times from the first sample).

    Use it on an envelope. The peak is refined by a parabola through its neighbours.

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan (an envelope).
    dt_s : float
        Sample interval (s).
    trace : int
        The trace searched.
    t_guess_s : float
        The window's centre (s from the first sample).
    half_window_s : float
        Half the window's length (s).

    Returns
    -------
    tuple of (float, float)
        ``(time_s, value)``; ``(nan, nan)`` when the window lies outside the record.
    """
    row = np.asarray(data[trace], dtype=np.float64)
    k0 = max(int(np.floor((t_guess_s - half_window_s) / dt_s)), 0)
    k1 = min(int(np.ceil((t_guess_s + half_window_s) / dt_s)), row.size - 1)
    if k1 <= k0:
        return float("nan"), float("nan")
    k = k0 + int(np.argmax(row[k0 : k1 + 1]))
    t, v = float(k), float(row[k])
    if 0 < k < row.size - 1:
        y0, y1, y2 = row[k - 1], row[k], row[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            d = 0.5 * (y0 - y2) / den
            t, v = k + d, y1 - 0.25 * (y0 - y2) * d
    return t * dt_s, v
