"""Traces and poses on one clock: survey-wheel triggering and poses at A-scan times.

A survey wheel fires a trace every ``spacing_m`` of travel; :func:`wheel_trigger_times` gives the times at which
it does from any distance record (the wheel's own counts, or a trajectory's path length). Poses at the trace times
come from :meth:`gpr3d.core.trajectory.Trajectory.at` (linear in position, SLERP in rotation, with the radar's
latency), or :func:`gpr3d.io.trajectory.attach_poses` for a Survey with timestamps.
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.trajectory import Trajectory

__all__ = ["wheel_trigger_times", "trajectory_triggers"]


def wheel_trigger_times(t_s, distance_m, spacing_m: float, *, start_m: float = 0.0) -> np.ndarray:
    """Times at which the travelled distance crosses ``start_m + k * spacing_m`` (k = 1, 2, ...).

    ``distance_m`` must not decrease (a wheel that rolls back does not fire again until it has made
    up the distance; pass its forward count). Stops give no traces.
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    d = np.asarray(distance_m, dtype=float).reshape(-1)
    if t.size != d.size or t.size < 2:
        raise InvalidDataError(f"times and distances must be two arrays of one length >= 2, got {t.size} and {d.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(d))):
        raise InvalidDataError("times or distances hold NaN/inf")
    if np.any(np.diff(t) <= 0):
        raise InvalidDataError("times must increase")
    if np.any(np.diff(d) < -1e-9):
        raise InvalidDataError("distance decreases: pass the wheel's forward count (it must not go down)")
    if not (np.isfinite(spacing_m) and spacing_m > 0):
        raise InvalidDataError(f"trace spacing must be a positive distance in metres, got {spacing_m!r}")
    marks = np.arange(start_m + spacing_m, d[-1] + 1e-12, spacing_m)
    keep = np.concatenate([[True], np.diff(d) > 0])  # the first sample of every stop
    return np.interp(marks, d[keep], t[keep])


def trajectory_triggers(traj: Trajectory, spacing_m: float) -> np.ndarray:
    """Survey-wheel trace times along a trajectory's path (the wheel measures the path the antenna travels)."""
    return wheel_trigger_times(traj.timestamps_s, traj.path_length_m(), spacing_m)
