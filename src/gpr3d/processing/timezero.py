"""Time zero: find when the wave leaves the surface, and cut the samples before it."""

from __future__ import annotations

import numpy as np

__all__ = ["first_break", "direct_wave_peak", "estimate_time_zero", "shift_traces"]


def first_break(data: np.ndarray, threshold: float = 0.1) -> np.ndarray:
    """First-break sample index of each trace (fractional).

    The first sample whose absolute amplitude reaches ``threshold`` times the trace's maximum absolute amplitude,
    refined by linear interpolation on the rising edge.

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    threshold : float
        In (0, 1].

    Returns
    -------
    ndarray
        ``(n_traces,)`` float array of sample indices.

    Raises
    ------
    ValueError
        A threshold outside (0, 1].
    """
    if not 0 < threshold <= 1:
        raise ValueError(f"threshold must be in (0, 1], got {threshold}")
    a = np.abs(np.asarray(data, dtype=np.float64))
    level = threshold * a.max(axis=1, keepdims=True)
    above = a >= level
    idx = np.argmax(above, axis=1)
    out = idx.astype(float)
    rows = np.nonzero(idx > 0)[0]
    if rows.size:
        i = idx[rows]
        lo, hi = a[rows, i - 1], a[rows, i]
        # sample i is the first to reach the level, so lo < level <= hi: the fraction lies in (0, 1]
        out[rows] = i - 1 + (level[rows, 0] - lo) / (hi - lo)
    return out


def direct_wave_peak(data: np.ndarray, search_samples: int | None = None, rel: float = 1.0) -> np.ndarray:
    """Sample index (fractional, parabolic refinement) of each trace's direct-wave peak.

    The peak is the **first** one of the absolute amplitude that reaches ``rel`` times the trace's largest (the
    default ``rel = 1``: the largest itself; a smaller ``rel`` skips echoes of shallow reflectors that outshine the
    direct wave, but can land on a side lobe of the direct wave itself).

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    search_samples : int, optional
        Search only the first samples of each trace, where the direct (air/ground) wave is.
    rel : float
        In (0, 1]: see above.

    Returns
    -------
    ndarray
        ``(n_traces,)`` float64 sample indices.

    Raises
    ------
    ValueError
        ``rel`` outside (0, 1].
    """
    if not 0 < rel <= 1:
        raise ValueError(f"rel must be in (0, 1], got {rel}")
    a = np.abs(np.asarray(data, dtype=np.float64))
    if search_samples is not None:
        a = a[:, : max(int(search_samples), 3)]
    level = rel * a.max(axis=1, keepdims=True)
    # a peak: not below its neighbours (the last sample counts when the search ends on a rising edge)
    left = np.concatenate([np.full((a.shape[0], 1), -np.inf), a[:, :-1]], axis=1)
    right = np.concatenate([a[:, 1:], np.full((a.shape[0], 1), -np.inf)], axis=1)
    cand = (a >= level) & (a >= left) & (a >= right)
    idx = np.argmax(cand, axis=1)
    out = idx.astype(float)
    inner = (idx > 0) & (idx < a.shape[1] - 1)
    r = np.nonzero(inner)[0]
    if r.size:
        i = idx[r]
        y0, y1, y2 = a[r, i - 1], a[r, i], a[r, i + 1]
        # the first peak reaching the level has y1 >= y0, y2 and y0 < y1 (were y0 = y1, sample i - 1 would be an
        # earlier peak): the parabola through the three is concave, its vertex within half a sample of i
        out[r] = i + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
    return out


def estimate_time_zero(
    data: np.ndarray,
    dt_s: float,
    *,
    method: str = "first_break",
    threshold: float = 0.1,
    search_s: float | None = None,
    per_trace: bool = False,
):
    """Time zero (s after the first sample) of a B-scan.

    ``method="first_break"`` uses :func:`first_break`; ``"peak"`` the direct-wave peak (:func:`direct_wave_peak`).
    With ``per_trace=False`` one value is returned: for ``"first_break"`` the median over traces, for ``"peak"`` the
    peak of the **mean trace**. The direct wave is the same in every trace and adds up; reflections move from trace
    to trace and average out. (The median of per-trace peaks fails where a shallow reflector outshines the direct
    wave in half the traces: a rebar mat under 6 cm of concrete put time zero on the bars' echo, 1.3 ns late.)

    Parameters
    ----------
    data, dt_s : (n_traces, n_samples) array, float
        The B-scan and its sample interval (s).
    method : {"first_break", "peak"}
        See above.
    threshold : float
        The first break's level, relative to each trace's largest amplitude.
    search_s : float, optional
        Search only this long from the first sample (s).
    per_trace : bool
        One value per trace instead of one for the B-scan.

    Returns
    -------
    float or ndarray
        Time zero (s), or ``(n_traces,)`` of them with ``per_trace``.

    Raises
    ------
    ValueError
        An unknown method.
    """
    if method == "first_break":
        idx = first_break(data, threshold)
    elif method == "peak":
        search = None if search_s is None else int(round(search_s / dt_s))
        a = np.asarray(data, dtype=np.float64)
        idx = direct_wave_peak(a if per_trace else a.mean(axis=0, keepdims=True), search)
    else:
        raise ValueError(f"unknown time-zero method {method!r} (use 'first_break' or 'peak')")
    t0 = idx * dt_s
    return t0 if per_trace else float(np.median(t0))


def shift_traces(data: np.ndarray, shift_samples) -> np.ndarray:
    """Move each trace earlier by ``shift_samples`` (fractional, linear interpolation).

    Samples that would come from beyond the end of a trace are not invented: the output is cut to the longest
    length that every trace can fill, i.e. ``floor(n_samples - 1 - max(shift)) + 1`` samples.

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    shift_samples : float or array_like
        One shift for all traces, or one per trace (samples, >= 0).

    Returns
    -------
    ndarray
        ``(n_traces, m)`` float32, ``m`` as above.

    Raises
    ------
    ValueError
        A negative shift, or one that leaves nothing.
    """
    x = np.asarray(data, dtype=np.float32)
    n_tr, n_s = x.shape
    shift = np.broadcast_to(np.asarray(shift_samples, dtype=float), (n_tr,))
    if np.any(shift < 0):
        raise ValueError("shifts must be >= 0 (time zero lies after the first sample)")
    n_out = int(np.floor(n_s - 1 - shift.max() + 1e-9)) + 1
    if n_out < 2:
        raise ValueError("time zero is at the end of the traces: nothing left after cutting")
    if np.all(shift == shift[0]):  # one shift for all: two slices instead of a gather per sample
        i0 = int(np.floor(shift[0]))
        w = np.float32(shift[0] - i0)
        lo = x[:, i0:i0 + n_out]
        hi = x[:, i0 + 1:i0 + 1 + n_out]
        if hi.shape[1] < n_out:  # the last output sample reads past the end: the last sample again (weight 0)
            hi = np.concatenate([hi, x[:, -1:]], axis=1)
        return (lo * (1 - w) + hi * w).astype(np.float32)
    pos = np.arange(n_out)[None, :] + shift[:, None]  # at most n_s - 1 (n_out above)
    i0 = np.floor(pos).astype(np.int64)
    i1 = np.minimum(i0 + 1, n_s - 1)
    w = (pos - i0).astype(np.float32)
    rows = np.arange(n_tr)[:, None]
    return (x[rows, i0] * (1 - w) + x[rows, i1] * w).astype(np.float32)
