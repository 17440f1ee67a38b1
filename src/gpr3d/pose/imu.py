"""IMU samples, visual-odometry relative poses, noise figures and the rotation helpers they share.

Frames (docs/CONVENTIONS.md): the world is right-handed with z up and gravity along -z; the body
frame is the IMU's; ``imu_T_camera`` is the camera's pose in the IMU frame (4 x 4). An IMU measures
the specific force ``R^T (a - g)`` (m/s^2) and the angular rate (rad/s), both in its own frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.inertial import ImuSamples, RelativePoses  # noqa: F401  (re-exported: they live in core)

__all__ = ["ImuNoise", "ImuSamples", "RelativePoses", "skew", "so3_exp", "so3_log", "GRAVITY"]

GRAVITY = 9.80665  #: m/s^2


def skew(v) -> np.ndarray:
    x, y, z = (float(a) for a in v)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def so3_exp(rotvec) -> np.ndarray:
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix()


def so3_log(R) -> np.ndarray:
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_rotvec()


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
