"""Antenna trajectories: TUM and CSV files, xyz tracks, and attaching poses to a survey.

A :class:`~gpr3d.core.trajectory.Trajectory` (the type lives in ``core``) holds
``timestamps_s (n,)``, ``positions_xyz (n, 3)`` and ``orientations_quat_wxyz (n, 4)``: poses ``world_from_antenna``. TUM files store
``t tx ty tz qx qy qz qw`` (quaternion last, w last); the conversion happens here.
"""

from __future__ import annotations

import csv
import io as _io

import numpy as np

from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.io._common import check_file

__all__ = ["Trajectory", "read_tum", "write_tum", "read_csv_trajectory", "read_trajectory", "read_xyz_track",
           "attach_poses", "attach_track", "read_track", "apply_track"]


def _rows(path, text: str, ncols: int, what: str) -> np.ndarray:
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        if len(parts) != ncols:
            raise FormatError(path, f"line {lineno}: expected {ncols} numbers ({what}), got {len(parts)}")
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            raise FormatError(path, f"line {lineno}: not a number in {line!r}") from None
        rows.append(vals)
    if not rows:
        raise FormatError(path, "holds no poses")
    arr = np.asarray(rows)
    if not np.all(np.isfinite(arr)):
        raise FormatError(path, "holds NaN/inf values")
    return arr


def _check_times(p, t) -> None:
    """Timestamps that run backwards are a broken or shuffled file, not a trajectory (equal ones pass: a cart at
    rest logged twice)."""
    back = np.nonzero(np.diff(t) < 0)[0]
    if back.size:
        i = int(back[0]) + 1
        raise FormatError(p, f"timestamps run backwards at pose {i} ({float(t[i])!r} s after {float(t[i - 1])!r} s)")


def read_tum(path) -> Trajectory:
    """Read a TUM trajectory (``t tx ty tz qx qy qz qw`` per line)."""
    p = check_file(path)
    arr = _rows(p, p.read_text(encoding="utf-8", errors="replace"), 8, "t tx ty tz qx qy qz qw")
    q = arr[:, [7, 4, 5, 6]]
    if np.any(np.linalg.norm(q, axis=1) < 1e-9):
        raise FormatError(p, "holds a zero quaternion")
    _check_times(p, arr[:, 0])
    return Trajectory(arr[:, 0], arr[:, 1:4], q)


def write_tum(traj: Trajectory, path) -> None:
    """Write a TUM trajectory atomically."""
    q = traj.orientations_quat_wxyz
    buf = _io.StringIO()
    buf.write("# t tx ty tz qx qy qz qw\n")
    for t, p, qq in zip(traj.timestamps_s, traj.positions_xyz, q):
        buf.write(" ".join(repr(float(v)) for v in (t, *p, qq[1], qq[2], qq[3], qq[0])) + "\n")
    atomic_write_text(path, buf.getvalue())


_CSV_NAMES = {
    "t": ("t", "time", "timestamp", "timestamp_s", "time_s"),
    "x": ("x", "tx", "px", "x_m"), "y": ("y", "ty", "py", "y_m"), "z": ("z", "tz", "pz", "z_m"),
    "qw": ("qw", "w"), "qx": ("qx",), "qy": ("qy",), "qz": ("qz",),
}


def read_csv_trajectory(path) -> Trajectory:
    """Read a CSV trajectory with a header naming columns t, x, y, z and (optionally) qw, qx, qy, qz; EuRoC MAV's
    ground truth (``#timestamp, p_RS_R_x [m], ..., q_RS_w [], ...``, nanoseconds) too."""
    p = check_file(path)
    text = p.read_text(encoding="utf-8", errors="replace")
    reader = csv.reader(_io.StringIO(text))
    from gpr3d.io.inertial import csv_header

    header, t_scale = csv_header(next(reader))  # (check_file refuses an empty file: a first row exists)
    cols = {}
    for key, names in _CSV_NAMES.items():
        for n in names:
            if n in header:
                cols[key] = header.index(n)
                break
    missing = [k for k in ("t", "x", "y", "z") if k not in cols]
    if missing:
        raise FormatError(p, f"CSV header lacks column(s) {missing} (has {header})")
    has_q = all(k in cols for k in ("qw", "qx", "qy", "qz"))
    rows = []
    for lineno, row in enumerate(reader, 2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            rows.append([float(row[cols[k]]) for k in ("t", "x", "y", "z")]
                        + ([float(row[cols[k]]) for k in ("qw", "qx", "qy", "qz")] if has_q else [1, 0, 0, 0]))
        except (ValueError, IndexError):
            raise FormatError(p, f"line {lineno}: bad or missing number") from None
    if not rows:
        raise FormatError(p, "holds no poses")
    arr = np.asarray(rows)
    if not np.all(np.isfinite(arr)):
        raise FormatError(p, "holds NaN/inf values")
    arr[:, 0] *= t_scale
    _check_times(p, arr[:, 0])
    return Trajectory(arr[:, 0], arr[:, 1:4], arr[:, 4:8])


def read_trajectory(path) -> Trajectory:
    """Read a TUM (``.txt``/``.tum``) or CSV (``.csv``) trajectory."""
    p = check_file(path)
    return read_csv_trajectory(p) if p.suffix.lower() == ".csv" else read_tum(p)


def read_xyz_track(path) -> np.ndarray:
    """Read a track of surveyed points, one ``x y z`` (or ``x,y,z``) per line, metres -> ``(n, 3)``."""
    p = check_file(path)
    return _rows(p, p.read_text(encoding="utf-8", errors="replace"), 3, "x y z")


def attach_poses(survey, traj: Trajectory, *, by: str = "index", latency_s: float = 0.0):
    """A new Survey whose traces carry poses from ``traj``.

    ``by="index"``: one pose per trace, in trace order (counts must match).
    ``by="time"``: poses interpolated at the survey's timestamps (linear positions,
    slerp orientations); traces outside the trajectory's time span are an error.
    ``latency_s`` (with ``by="time"``): the radar's clock runs this much behind the trajectory's.
    """
    if by == "index":
        if len(traj) != survey.n_traces:
            raise InvalidDataError(f"trajectory has {len(traj)} poses but the survey has {survey.n_traces} traces")
        pos, q, t = traj.positions_xyz, traj.orientations_quat_wxyz, traj.timestamps_s
    elif by == "time":
        if survey.timestamps_s is None:
            raise InvalidDataError("survey has no timestamps to interpolate poses at")
        at = traj.at(survey.timestamps_s, latency_s=latency_s)
        pos, q, t = at.positions_xyz, at.orientations_quat_wxyz, at.timestamps_s
    else:
        raise InvalidDataError(f"by must be 'index' or 'time', got {by!r}")
    out = survey.replace(positions_xyz=pos, orientations_quat_wxyz=q, timestamps_s=t)
    out.metadata["positions_source"] = f"trajectory ({by})"
    return out


def attach_track(survey, track_xyz: np.ndarray):
    """Place a straight-line survey on a surveyed 3D track (e.g. GPS/total-station points).

    Each trace's along-line distance (its x position, from the survey wheel or
    trace headers) is matched to the cumulative horizontal distance along the
    track; positions are interpolated there and headings follow the track.
    """
    from gpr3d.core.poses import quat_from_yaw

    if survey.positions_xyz is None:
        raise InvalidDataError("survey has no along-line positions to place on the track")
    track = np.asarray(track_xyz, dtype=float)
    if track.ndim != 2 or track.shape[1] != 3 or track.shape[0] < 2:
        raise InvalidDataError("track must be (n >= 2, 3) points")
    s_track = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(track[:, :2], axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(s_track) > 0])  # a point repeated in plan (a vertical step) adds no way
    track, s_track = track[keep], s_track[keep]
    s = survey.positions_xyz[:, 0] - survey.positions_xyz[0, 0]
    pos = np.stack([np.interp(s, s_track, track[:, k]) for k in range(3)], axis=1)
    seg = np.clip(np.searchsorted(s_track, s, side="right") - 1, 0, track.shape[0] - 2)
    d = track[seg + 1] - track[seg]
    out = survey.replace(positions_xyz=pos, orientations_quat_wxyz=quat_from_yaw(np.arctan2(d[:, 1], d[:, 0])))
    out.metadata["positions_source"] = "along-line distance placed on an xyz track"
    if s[-1] > s_track[-1] * 1.05:
        out.metadata["track_warning"] = f"survey line {s[-1]:.2f} m is longer than the track {s_track[-1]:.2f} m"
    return out


def read_track(path):
    """A surveyed track for :func:`apply_track`: ``("points", (n, 3) xyz)`` from an ``x y z`` text file or a CSV
    whose header names x, y, z (optionally more columns), or ``("per_trace", (trace_index, (k, 3) local ENU m))``
    from a GSSI ``.DZG`` (GPS fixes tagged with their scan number, in metres east/north/up from the first fix)."""
    p = check_file(path)
    ext = p.suffix.lower()
    if ext == ".dzg":
        from gpr3d.io._common import gps_positions
        from gpr3d.io.dzt import read_dzg

        g = read_dzg(p)
        if len(g["scan"]) < 2:
            raise FormatError(p, f"holds {len(g['scan'])} GPS fix(es) with a fix quality > 0: two at least needed")
        scans = np.asarray(g["scan"], float)
        pos, _origin = gps_positions(scans, np.asarray(g["lat"]), np.asarray(g["lon"]), np.asarray(g["alt"]),
                                     scans)
        if pos is None:
            raise FormatError(p, "GPS fixes do not advance with the scan number")
        return "per_trace", (scans, pos)
    text = p.read_text(encoding="utf-8", errors="replace")
    if ext == ".csv":
        reader = csv.reader(_io.StringIO(text))
        header = [h.strip().lower() for h in next(reader)]  # (check_file refuses an empty file)
        cols = {}
        for key in ("x", "y", "z"):
            found = [header.index(n) for n in _CSV_NAMES[key] if n in header]
            if not found:
                raise FormatError(p, f"CSV header lacks a {key} column (has {header})")
            cols[key] = found[0]
        rows = []
        for lineno, row in enumerate(reader, 2):
            if not row or all(not c.strip() for c in row):
                continue
            try:
                rows.append([float(row[cols[k]]) for k in ("x", "y", "z")])
            except (ValueError, IndexError):
                raise FormatError(p, f"line {lineno}: x, y, z must be numbers, got {row}") from None
        pts = np.asarray(rows, float).reshape(-1, 3)
    else:
        pts = _rows(p, text, 3, "x y z")
    if len(pts) < 2 or not np.all(np.isfinite(pts)):
        raise FormatError(p, "a track needs two finite x y z points at least")
    return "points", pts


def apply_track(survey, track) -> "object":
    """Place ``survey`` on a track from :func:`read_track`: along an xyz track by each trace's along-line
    distance (:func:`attach_track`), or on GPS fixes by trace number (linear between fixes; traces before the
    first fix or after the last take the nearest fix's position, and are reported in the metadata)."""
    kind, value = track
    if kind == "points":
        return attach_track(survey, value)
    scans, pos = value
    idx = np.arange(survey.n_traces, dtype=float)
    xyz = np.stack([np.interp(idx, scans, pos[:, k]) for k in range(3)], axis=1)
    outside = int(np.count_nonzero((idx < scans[0]) | (idx > scans[-1])))
    from gpr3d.core.poses import quat_from_yaw

    d = np.gradient(xyz[:, :2], axis=0)
    out = survey.replace(positions_xyz=xyz, orientations_quat_wxyz=quat_from_yaw(np.arctan2(d[:, 1], d[:, 0])))
    out.metadata["positions_source"] = "GPS fixes by trace number"
    if outside:
        out.metadata["track_warning"] = f"{outside} traces lie outside the GPS fixes' span"
    return out
