"""IMU and survey-wheel recordings as CSV, and the rig file (mounts and latency) that ``gpr3d pose`` reads.

* IMU CSV: a header naming ``t, ax, ay, az, gx, gy, gz`` (seconds, m/s^2 specific force, rad/s), one sample a row;
  or EuRoC MAV's ``imu0/data.csv`` (``#timestamp [ns], w_RS_S_x [rad s^-1], ..., a_RS_S_z [m s^-2]``).
* Wheel CSV: a header naming ``t, distance`` (seconds on the IMU clock, forward metres).
* Rig JSON: ``{"imu_T_camera": 4x4, "imu_T_antenna": 4x4, "camera_time_offset_s": s}`` (CONVENTIONS.md).

Visual odometry comes as a TUM trajectory of camera poses (:func:`gpr3d.io.trajectory.read_tum`);
:func:`relative_from_camera_poses` turns it into frame-to-frame motions, and a jump in the frame times
(lost tracking) into a gap.
"""

from __future__ import annotations

import csv
import io as _io
import json

import numpy as np
from scipy.spatial.transform import Rotation

from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.io._common import check_file

__all__ = ["read_imu_csv", "write_imu_csv", "read_wheel_csv", "write_wheel_csv", "read_rig", "write_rig",
           "relative_from_camera_poses", "CameraMotions"]

IMU_COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")


#: EuRoC MAV (ASL) column names -> ours; its times are integer nanoseconds
EUROC_NAMES = {"#timestamp": "t", "timestamp": "t", "w_rs_s_x": "gx", "w_rs_s_y": "gy", "w_rs_s_z": "gz",
               "a_rs_s_x": "ax", "a_rs_s_y": "ay", "a_rs_s_z": "az", "p_rs_r_x": "x", "p_rs_r_y": "y",
               "p_rs_r_z": "z", "q_rs_w": "qw", "q_rs_x": "qx", "q_rs_y": "qy", "q_rs_z": "qz"}


def csv_header(names: list) -> tuple[list, float]:
    """Column names lower-cased, with EuRoC's (``#timestamp [ns]``, ``w_RS_S_x [rad s^-1]``, ``p_RS_R_x [m]``...)
    mapped to ours; and the factor that turns the time column into seconds (1e-9 for EuRoC's nanoseconds)."""
    out, scale = [], 1.0
    for h in names:
        h = h.strip().lower()
        base = h.split("[")[0].strip()
        if base in EUROC_NAMES and (base.startswith("#") or "_rs_" in base or "[ns]" in h):
            if EUROC_NAMES[base] == "t":
                scale = 1e-9
            h = EUROC_NAMES[base]
        out.append(h)
    return out, scale


def _read_columns(path, names: tuple, what: str) -> np.ndarray:
    p = check_file(path)
    reader = csv.reader(_io.StringIO(p.read_text(encoding="utf-8", errors="replace")))
    try:
        header, t_scale = csv_header(next(reader))
    except StopIteration:
        raise FormatError(p, "empty CSV") from None
    missing = [n for n in names if n not in header]
    if missing:
        raise FormatError(p, f"{what} CSV header lacks column(s) {missing} (has {header})")
    idx = [header.index(n) for n in names]
    rows = []
    for lineno, row in enumerate(reader, 2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            rows.append([float(row[i]) for i in idx])
        except (ValueError, IndexError):
            raise FormatError(p, f"line {lineno}: bad or missing number") from None
    if len(rows) < 2:
        raise FormatError(p, f"holds {len(rows)} {what} sample(s); two at least are needed")
    arr = np.asarray(rows)
    if not np.all(np.isfinite(arr)):
        raise FormatError(p, "holds NaN/inf values")
    if names[0] == "t" and t_scale != 1.0:
        arr[:, 0] *= t_scale  # EuRoC nanoseconds (1e18: float64 keeps them to ~0.3 us)
    return arr


def read_imu_csv(path):
    """Read IMU samples (:class:`gpr3d.core.inertial.ImuSamples`; units are checked there)."""
    from gpr3d.core.inertial import ImuSamples

    a = _read_columns(path, IMU_COLUMNS, "IMU")
    try:
        return ImuSamples(a[:, 0], a[:, 1:4], a[:, 4:7])
    except InvalidDataError as exc:
        raise FormatError(check_file(path), str(exc)) from None


def write_imu_csv(imu, path) -> None:
    buf = _io.StringIO()
    buf.write(",".join(IMU_COLUMNS) + "\n")
    for t, a, g in zip(imu.t_s, imu.accel, imu.gyro):
        buf.write(f"{t:.6f},{a[0]:.7g},{a[1]:.7g},{a[2]:.7g},{g[0]:.7g},{g[1]:.7g},{g[2]:.7g}\n")
    atomic_write_text(path, buf.getvalue())


def read_wheel_csv(path) -> tuple[np.ndarray, np.ndarray]:
    a = _read_columns(path, ("t", "distance"), "wheel")
    return a[:, 0], a[:, 1]


def write_wheel_csv(t_s, distance_m, path) -> None:
    atomic_write_text(path, "t,distance\n" + "".join(f"{t:.6f},{d:.4f}\n" for t, d in zip(t_s, distance_m)))


def read_rig(path) -> dict:
    p = check_file(path)
    try:
        d = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise FormatError(p, f"not JSON ({exc.msg}, line {exc.lineno})") from None
    out = {}
    for key in ("imu_T_camera", "imu_T_antenna"):
        if key in d:
            T = np.asarray(d[key], dtype=float)
            if T.shape != (4, 4):
                raise FormatError(p, f"{key} must be a 4 x 4 matrix, got shape {T.shape}")
            out[key] = T
    if "camera_time_offset_s" in d:
        out["camera_time_offset_s"] = float(d["camera_time_offset_s"])
    unknown = set(d) - {"imu_T_camera", "imu_T_antenna", "camera_time_offset_s"}
    if unknown:
        raise FormatError(p, f"unknown rig key(s) {sorted(unknown)}")
    return out


def write_rig(path, *, imu_T_camera, imu_T_antenna, camera_time_offset_s: float) -> None:
    atomic_write_text(path, json.dumps({"imu_T_camera": np.asarray(imu_T_camera).tolist(),
                                        "imu_T_antenna": np.asarray(imu_T_antenna).tolist(),
                                        "camera_time_offset_s": camera_time_offset_s}, indent=1))


def _motions(R, p):
    """The motions from each camera pose to the next (``R``: ``(n, 3, 3)``, ``p``: ``(n, 3)``): ``n - 1`` rotations
    and translations (in the earlier frame)."""
    return np.einsum("nji,njk->nik", R[:-1], R[1:]), np.einsum("nji,nj->ni", R[:-1], p[1:] - p[:-1])


def _motion_cov(p_rel, rot_sigma_deg, trans_frac, trans_floor_m):
    """The motions' covariances: rotation per axis; translation a share of the step plus a floor."""
    st = trans_frac * np.linalg.norm(p_rel, axis=1) + trans_floor_m
    cov = np.zeros((len(p_rel), 6, 6))
    cov[:, :3, :3] = np.eye(3) * np.deg2rad(rot_sigma_deg) ** 2
    cov[:, 3:, 3:] = np.eye(3)[None] * (st**2)[:, None, None]
    return cov


def relative_from_camera_poses(traj: Trajectory, *, rot_sigma_deg: float = 0.03, trans_frac: float = 0.01,
                               trans_floor_m: float = 5e-4, gap_factor: float = 1.5):
    """Frame-to-frame camera motions (:class:`gpr3d.core.inertial.RelativePoses`) from odometry's camera poses.

    Each motion gets the covariance of the noise figures given (rotation per axis; translation a share of
    the step plus a floor). A frame interval longer than ``gap_factor`` times the median is lost tracking:
    the motion across it is unknown.
    """
    from gpr3d.core.inertial import RelativePoses

    t = traj.timestamps_s
    if t.size < 2:
        raise InvalidDataError("odometry holds fewer than two frames")
    R = Rotation.from_quat(traj.orientations_quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()
    n = t.size
    R_rel = np.tile(np.eye(3), (n, 1, 1))
    p_rel = np.zeros((n, 3))
    R_rel[1:], p_rel[1:] = _motions(R, traj.positions_xyz)
    cov = _motion_cov(p_rel, rot_sigma_deg, trans_frac, trans_floor_m)
    dt = np.diff(t)
    valid = np.concatenate([[False], dt <= gap_factor * np.median(dt)])
    return RelativePoses(t, R_rel, p_rel, cov, valid)


class CameraMotions:
    """:func:`relative_from_camera_poses` for camera poses that come as the survey runs: :meth:`add` takes the
    next frames and gives their motions from the frame before. A frame interval longer than ``gap_factor``
    times the median of the intervals up to it is lost tracking (the whole record's median decides in the
    batch function: the same where the frame rate is steady)."""

    def __init__(self, *, rot_sigma_deg: float = 0.03, trans_frac: float = 0.01, trans_floor_m: float = 5e-4,
                 gap_factor: float = 1.5):
        self.sigma = (rot_sigma_deg, trans_frac, trans_floor_m)
        self.gap_factor = gap_factor
        self._last = None  # (t, R, p) of the newest frame
        self._dts: list = []  # the frame intervals so far, sorted

    def add(self, t_s, positions_xyz, quats_wxyz):
        """``(t, R, p, cov, valid)`` of the frames given (times increasing, after those given before; unit
        quaternions ``qw qx qy qz``), as :meth:`gpr3d.pose.eskf.ForwardFusion.add_frames` takes them."""
        import bisect

        t = np.asarray(t_s, float).reshape(-1)
        n = t.size
        R = Rotation.from_quat(np.asarray(quats_wxyz, float).reshape(n, 4)[:, [1, 2, 3, 0]]).as_matrix()
        p = np.asarray(positions_xyz, float).reshape(n, 3)
        valid = np.zeros(n, bool)
        R_rel, p_rel = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
        if n:
            tt, RR, pp = (t, R, p) if self._last is None else (np.r_[self._last[0], t], np.r_[self._last[1][None], R],
                                                               np.r_[self._last[2][None], p])
            m = len(tt) - 1
            if m:
                R_rel[n - m:], p_rel[n - m:] = _motions(RR, pp)
            for k, dt in enumerate(np.diff(tt)):
                bisect.insort(self._dts, dt)
                d = self._dts
                med = d[len(d) // 2] if len(d) % 2 else 0.5 * (d[len(d) // 2 - 1] + d[len(d) // 2])
                valid[n - m + k] = dt <= self.gap_factor * med
            self._last = (t[-1], R[-1], p[-1])
        return t, R_rel, p_rel, _motion_cov(p_rel, *self.sigma), valid
