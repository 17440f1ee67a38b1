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

__all__ = ["wheel_trigger_times", "trajectory_triggers", "estimate_time_offset"]


def wheel_trigger_times(t_s, distance_m, spacing_m: float, *, start_m: float = 0.0) -> np.ndarray:
    """Times at which the travelled distance crosses ``start_m + k * spacing_m`` (k = 1, 2, ...).

    ``distance_m`` must not decrease (a wheel that rolls back does not fire again until it has made
    up the distance; pass its forward count). Stops give no traces: a mark at a stop's distance fires when the
    wheel gets there, the next one after it moves on. Marks the wheel had passed before the first sample give none.
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
    marks = marks[marks > d[0]]  # the wheel had passed those before the record began
    # each mark between the last sample short of it and the first that reaches it: a mark at a stop's distance
    # fires on arrival, one past it after the wheel moves on (however long the stop)
    i = np.clip(np.searchsorted(d, marks, side="left"), 1, d.size - 1)
    frac = (marks - d[i - 1]) / (d[i] - d[i - 1])
    return t[i - 1] + np.clip(frac, 0.0, 1.0) * (t[i] - t[i - 1])


def trajectory_triggers(traj: Trajectory, spacing_m: float) -> np.ndarray:
    """Survey-wheel trace times along a trajectory's path (the wheel measures the path the antenna travels)."""
    return wheel_trigger_times(traj.timestamps_s, traj.path_length_m(), spacing_m)


def estimate_time_offset(imu, vo, *, max_offset_s: float = 0.2, step_s: float = 0.0005) -> dict:
    """The camera-IMU time offset (IMU time of a frame = its camera stamp + offset) from the data alone.

    The angle the camera turns between two frames (odometry) and the angle the gyro integrates over the same
    interval on the IMU clock agree only at the right offset (an angle does not depend on the frame it is
    measured in, so the mount's rotation need not be known). The offset minimises their squared difference over
    all registered frames, searched on a ``step_s`` grid within ``+-max_offset_s`` and refined by a parabola.
    Frames whose angles disagree past 5 robust sigmas at the first estimate (odometry's gross errors) are left
    out of a second pass. The gyro bias is taken from the run's median rate where odometry sees no turn. Needs turns: the result's
    ``turn_deg`` is the total turn it rests on, and ``sharpness`` the curvature of the cost at its minimum
    (relative; under ~1 the offset is poorly fixed).
    """
    from gpr3d.pose.imu import so3_log

    if not (np.isfinite(max_offset_s) and max_offset_s > 0 and np.isfinite(step_s) and 0 < step_s < max_offset_s):
        raise InvalidDataError(f"max_offset_s and step_s must be positive, step_s the smaller; got {max_offset_s!r}, "
                               f"{step_s!r}")
    k = np.nonzero(vo.valid)[0]
    k = k[(vo.t_s[k - 1] - max_offset_s >= imu.t_s[0]) & (vo.t_s[k] + max_offset_s <= imu.t_s[-1])]
    if k.size < 10:
        raise InvalidDataError(f"too few odometry frames ({k.size}) overlap the IMU record to estimate an offset")
    ang_vo = np.array([np.linalg.norm(so3_log(vo.R[i])) for i in k])
    still = ang_vo <= np.percentile(ang_vo, 20)  # (<=: frames that did not turn at all tie at the percentile)
    t0, t1 = vo.t_s[k - 1], vo.t_s[k]
    # gyro bias from the quietest fifth of the frames (odometry sees no turn there)
    quiet = np.zeros(imu.t_s.size, bool)
    for a, b in zip(t0[still], t1[still]):
        quiet[(imu.t_s >= a) & (imu.t_s <= b)] = True
    bias = np.median(imu.gyro[quiet], axis=0) if quiet.sum() >= 10 else np.zeros(3)
    w = imu.gyro - bias
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(imu.t_s)[:, None], axis=0)])

    def angles(offset):
        a = np.stack([np.interp(t0 + offset, imu.t_s, cum[:, j]) for j in range(3)], -1)
        b = np.stack([np.interp(t1 + offset, imu.t_s, cum[:, j]) for j in range(3)], -1)
        return np.linalg.norm(b - a, axis=1)

    grid = np.arange(-max_offset_s, max_offset_s + 0.5 * step_s, step_s)
    A = np.array([angles(o) for o in grid])  # (offsets, frames)
    keep = np.ones(k.size, bool)
    for _ in range(2):  # the second pass leaves out odometry's gross errors (residuals past 5 robust sigmas)
        cost = np.mean((A[:, keep] - ang_vo[keep]) ** 2, axis=1)
        i = int(np.argmin(cost))
        r = A[i] - ang_vo
        # (at least 1e-4 rad: odometry's angles are never better, and a run that agrees exactly keeps its frames)
        sigma = max(1.4826 * np.median(np.abs(r - np.median(r))), 1e-4)
        keep = np.abs(r - np.median(r)) < 5 * sigma
    best = float(grid[i])
    curv = 0.0
    if 0 < i < grid.size - 1:
        c0, c1, c2 = cost[i - 1], cost[i], cost[i + 1]
        den = c0 - 2 * c1 + c2
        if den > 0:
            best += 0.5 * step_s * (c0 - c2) / den
            curv = den / step_s**2
    at_edge = i in (0, grid.size - 1)
    return {"offset_s": best, "at_search_edge": bool(at_edge), "frames": int(keep.sum()),
            "turn_deg": float(np.degrees(ang_vo.sum())),
            "sharpness": float(curv * (0.01**2) / max(cost[i], 1e-18))}
