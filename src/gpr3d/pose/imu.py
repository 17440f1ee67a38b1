"""IMU samples, visual-odometry relative poses, noise figures and the rotation helpers they share.

Frames (docs/CONVENTIONS.md): the world is right-handed with z up and gravity along -z; the body
frame is the IMU's; ``imu_T_camera`` is the camera's pose in the IMU frame (4 x 4). An IMU measures
the specific force ``R^T (a - g)`` (m/s^2) and the angular rate (rad/s), both in its own frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.inertial import ImuSamples, RelativePoses  # noqa: F401  (re-exported: they live in core)

__all__ = ["ImuNoise", "ImuSamples", "RelativePoses", "skew", "so3_exp", "so3_log", "GRAVITY"]

GRAVITY = 9.80665  #: m/s^2


def skew(v) -> np.ndarray:
    x, y, z = np.asarray(v).tolist()  # (Python numbers: the 0.0 entries make the matrix float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def so3_exp(rotvec) -> np.ndarray:
    """The rotation matrix of a rotation vector (its axis times its angle, rad); ``(..., 3)`` gives ``(..., 3, 3)``.

    One vector (what the filter asks at every IMU sample) by Rodrigues' formula in scalar arithmetic, ten times
    faster than SciPy's ``Rotation`` for one (its per-call overhead was half of the pose fusion's time,
    ``benchmarks/results/intel/bench_pose.md``); several by SciPy."""
    w = np.asarray(rotvec)
    if w.shape != (3,):
        return Rotation.from_rotvec(w).as_matrix()
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    t2 = x * x + y * y + z * z
    if not math.isfinite(t2):  # NaN or inf: NaN, as SciPy gives (math.sin of inf would raise)
        return Rotation.from_rotvec(w).as_matrix()  # (a NaN or inf makes w float already)
    if t2 < 1e-8:  # sin(t)/t and (1 - cos t)/t^2 by their series (what is left out moves R by under 1e-17)
        a = 1.0 - t2 / 6.0
        b = 0.5
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    c = 1.0 - b * t2  # cos t
    bx, by, bz = b * x, b * y, b * z
    return np.array([[c + bx * x, bx * y - a * z, bx * z + a * y],
                     [bx * y + a * z, c + by * y, by * z - a * x],
                     [bx * z - a * y, by * z + a * x, c + bz * z]])


def so3_log(R) -> np.ndarray:
    """The rotation vector of a rotation matrix (the inverse of :func:`so3_exp`, angle in [0, pi]); ``(..., 3, 3)``
    gives ``(..., 3)``. One matrix by its quaternion (Shepperd's choice of the largest of the four terms, well
    conditioned at any angle, half a turn included), in scalar arithmetic; several by SciPy."""
    m = np.asarray(R)
    if m.shape != (3, 3):
        return Rotation.from_matrix(m).as_rotvec()
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = m.tolist()
    tr = r00 + r11 + r22
    # the four terms 1 + tr, 1 + 2 r00 - tr, ... (4 w^2, 4 x^2, ...) sum to 4 for any matrix: the largest is >= 1
    if tr >= r00 and tr >= r11 and tr >= r22:
        w = 0.5 * math.sqrt(1.0 + tr)
        k = 0.25 / w
        x, y, z = (r21 - r12) * k, (r02 - r20) * k, (r10 - r01) * k
    elif r00 >= r11 and r00 >= r22:
        x = 0.5 * math.sqrt(1.0 + r00 - r11 - r22)
        k = 0.25 / x
        w, y, z = (r21 - r12) * k, (r01 + r10) * k, (r02 + r20) * k
    elif r11 >= r22:
        y = 0.5 * math.sqrt(1.0 - r00 + r11 - r22)
        k = 0.25 / y
        w, x, z = (r02 - r20) * k, (r01 + r10) * k, (r12 + r21) * k
    else:
        z = 0.5 * math.sqrt(1.0 - r00 - r11 + r22)
        k = 0.25 / z
        w, x, y = (r10 - r01) * k, (r02 + r20) * k, (r12 + r21) * k
    if w < 0.0:  # the same rotation, the angle in [0, pi]
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    # angle / sin(angle / 2) from the quaternion; below 1e-7 its limit 2 (relative error n^2 / 3: under 4e-15)
    scale = 2.0 * math.atan2(n, w) / n if n > 1e-7 else 2.0
    return np.array([x * scale, y * scale, z * scale])


@dataclass
class ImuNoise:
    """Continuous-time IMU noise figures (the defaults: a Bosch BMI055, the D435i's IMU, from its datasheet:
    accelerometer 150 ug/sqrt(Hz), gyroscope 0.014 deg/s/sqrt(Hz); bias random walks of a consumer MEMS part).

    Attributes
    ----------
    accel_noise : float
        Accelerometer white noise, m/s^2/sqrt(Hz).
    gyro_noise : float
        Gyroscope white noise, rad/s/sqrt(Hz).
    accel_bias_walk : float
        Accelerometer bias random walk, m/s^3/sqrt(Hz).
    gyro_bias_walk : float
        Gyroscope bias random walk, rad/s^2/sqrt(Hz).

    Raises
    ------
    InvalidDataError
        A figure that is not a positive number.
    """

    accel_noise: float = 150e-6 * GRAVITY  #: m/s^2/sqrt(Hz)
    gyro_noise: float = np.deg2rad(0.014)  #: rad/s/sqrt(Hz)
    accel_bias_walk: float = 3e-4  #: m/s^3/sqrt(Hz)
    gyro_bias_walk: float = 2e-5  #: rad/s^2/sqrt(Hz)

    def __post_init__(self):
        for name in ("accel_noise", "gyro_noise", "accel_bias_walk", "gyro_bias_walk"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InvalidDataError(f"IMU {name.replace('_', ' ')} must be a positive number, got {v!r}")
