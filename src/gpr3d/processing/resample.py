"""Traces at a constant spacing along the antenna's path."""

from __future__ import annotations

import numpy as np

__all__ = ["path_distance", "resample_traces"]


def path_distance(positions_xyz: np.ndarray) -> np.ndarray:
    """Cumulative distance (m) along a polyline of positions.

    Parameters
    ----------
    positions_xyz : (n, 3) array
        The path's points.

    Returns
    -------
    ndarray
        ``(n,)`` float64, starting at 0.
    """
    p = np.asarray(positions_xyz, dtype=float)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def resample_traces(
    data: np.ndarray, positions_xyz: np.ndarray, spacing_m: float, *, min_step_m: float | None = None
):
    """Interpolate traces to a constant spacing along the path.

    Traces recorded while the antenna stood still (steps below ``min_step_m``) are merged by keeping the first of
    each run. New traces are linear blends of the two recorded neighbours along the path.

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.
    positions_xyz : (n_traces, 3) array
        The antenna's position per trace.
    spacing_m : float
        The new spacing (m), > 0.
    min_step_m : float, optional
        Steps below it count as standing still (default ``spacing_m / 100``).

    Returns
    -------
    data_new : (m, n_samples) float32
        The resampled traces.
    distance_new : (m,) ndarray
        Path distance of each new trace (m).
    source_index : (m,) ndarray
        Fractional index into the input traces, for interpolating any other per-trace quantity (positions, times,
        poses).

    Raises
    ------
    ValueError
        A spacing that is not positive, or a path shorter than one spacing.
    """
    if not spacing_m > 0:
        raise ValueError(f"spacing_m must be > 0, got {spacing_m}")
    x = np.asarray(data, dtype=np.float32)
    s = path_distance(positions_xyz)
    min_step = spacing_m / 100 if min_step_m is None else min_step_m
    keep = np.concatenate([[True], np.diff(s) > min_step])
    # a run of standing traces keeps its first; path distance stays strictly increasing
    idx = np.nonzero(keep)[0]
    s_keep = s[idx]  # s_keep[0] = 0: the first trace is always kept
    if s_keep[-1] < spacing_m:
        raise ValueError(f"the path is {s_keep[-1]:.3g} m long, shorter than one spacing of {spacing_m:g} m")
    s_new = np.arange(0.0, s_keep[-1] + 1e-9 * spacing_m, spacing_m)
    frac_kept = np.interp(s_new, s_keep, np.arange(idx.size))  # in [0, idx.size - 1]
    j0 = np.floor(frac_kept).astype(np.int64)
    j1 = np.minimum(j0 + 1, idx.size - 1)
    w = (frac_kept - j0).astype(np.float32)[:, None]
    out = x[idx[j0]] * (1 - w) + x[idx[j1]] * w
    source_index = idx[j0] + (idx[j1] - idx[j0]) * w[:, 0]
    return out.astype(np.float32), s_new, source_index.astype(float)
