"""IMU samples and visual odometry's relative poses: the sensor data ``io`` reads and ``pose`` fuses.

Frames and units (docs/CONVENTIONS.md): an IMU measures the specific force ``R^T (a - g)`` (m/s^2) and the
angular rate (rad/s) in its own frame; odometry gives frame ``k``'s camera pose in frame ``k - 1`` (or in a
keyframe before it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["ImuSamples", "RelativePoses"]


def _times(t, what: str) -> np.ndarray:
    t = np.asarray(t, dtype=float).reshape(-1)
    if t.size < 2:
        raise InvalidDataError(f"{what}: at least two samples are needed, got {t.size}")
    if not np.all(np.isfinite(t)):
        raise InvalidDataError(f"{what}: timestamps hold NaN/inf")
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise InvalidDataError(f"{what}: timestamps must increase (sample {k + 1} at {t[k + 1]:.6f} s follows "
                               f"{t[k]:.6f} s)")
    return t


@dataclass
class ImuSamples:
    """IMU samples: times (s), specific force (m/s^2) and angular rate (rad/s) in the IMU frame."""

    t_s: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray

    def __post_init__(self):
        self.t_s = _times(self.t_s, "IMU")
        n = self.t_s.size
        for name in ("accel", "gyro"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (n, 3):
                raise InvalidDataError(f"IMU {name}: expected {n} x 3 values, got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise InvalidDataError(f"IMU {name} holds NaN/inf (sample {int(np.argmax(~np.isfinite(a).all(1)))})")
            setattr(self, name, a)
        g = np.median(np.linalg.norm(self.accel, axis=1))
        if not 2.0 < g < 40.0:  # m/s^2: an IMU at rest or on a cart reads about 9.8
            hint = " (in g? multiply by 9.80665)" if 0.2 < g < 4 else ""
            raise InvalidDataError(f"IMU accel: median magnitude {g:.3g} is not in m/s^2{hint}")
        w = np.percentile(np.abs(self.gyro), 99)
        if w > 35.0:  # rad/s: a cart never turns that fast; deg/s read as rad/s does
            raise InvalidDataError(f"IMU gyro: rates up to {w:.3g} are not in rad/s (deg/s? multiply by pi/180)")

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t_s)))


@dataclass
class RelativePoses:
    """Visual odometry as relative camera motions, each from a reference frame.

    ``t_s[k]`` is frame ``k``'s time (camera clock); for ``k >= 1`` ``R[k]``, ``p[k]`` are frame ``k``'s pose in
    frame ``ref[k]`` (``camera_ref T camera_k``), ``cov[k]`` the 6 x 6 covariance of its error, rotation first
    (right perturbation ``R Exp(d_theta)``, then additive translation), and ``valid[k]`` is False where odometry
    failed (no motion is known from frame ``ref[k]`` to ``k``). Entry 0 is unused.

    ``ref`` (default ``k - 1``: frame to frame) lets odometry register frames to a keyframe: a frame's reference
    is the previous frame (which thereby becomes the keyframe) or the previous frame's reference (the same
    keyframe), so that one keyframe is live at a time.
    """

    t_s: np.ndarray
    R: np.ndarray
    p: np.ndarray
    cov: np.ndarray
    valid: np.ndarray = field(default=None)
    ref: np.ndarray = field(default=None)

    def __post_init__(self):
        self.t_s = _times(self.t_s, "visual odometry")
        n = self.t_s.size
        self.R = np.asarray(self.R, dtype=float).reshape(n, 3, 3)
        self.p = np.asarray(self.p, dtype=float).reshape(n, 3)
        self.cov = np.asarray(self.cov, dtype=float).reshape(n, 6, 6)
        self.valid = np.ones(n, bool) if self.valid is None else np.asarray(self.valid, bool).reshape(n)
        self.valid[0] = False
        bad = ~(np.isfinite(self.R).all((1, 2)) & np.isfinite(self.p).all(1) & np.isfinite(self.cov).all((1, 2)))
        self.valid &= ~bad
        if self.ref is None:
            self.ref = np.arange(n) - 1
        else:
            r = np.asarray(self.ref)
            if r.shape != (n,) or not np.all(np.isfinite(r)) or np.any(r != np.round(r)):
                raise InvalidDataError(f"visual odometry ref: expected {n} whole frame indices, got shape {r.shape}")
            r = r.astype(int)
            r[0] = -1
            ok = (r[1:] == np.arange(n - 1)) | (r[1:] == r[:-1])
            ok[0] = r[1] == 0
            if not ok.all():
                k = int(np.argmin(ok)) + 1
                raise InvalidDataError(f"visual odometry ref: frame {k} refers to frame {r[k]}; a frame's reference "
                                       f"must be the previous frame ({k - 1}) or the previous frame's reference")
            self.ref = r

    @property
    def keyframes(self) -> bool:
        """True when some motion refers to a frame other than the one before."""
        return bool(np.any(self.ref[1:] != np.arange(self.t_s.size - 1)))

    def chained(self) -> tuple[np.ndarray, np.ndarray]:
        """Camera poses ``camera_0 T camera_k`` from chaining the motions (a failed frame holds the pose of the
        frame before)."""
        n = self.t_s.size
        R = np.empty((n, 3, 3))
        p = np.empty((n, 3))
        R[0], p[0] = np.eye(3), np.zeros(3)
        for k in range(1, n):
            j = self.ref[k]
            if self.valid[k]:
                p[k] = p[j] + R[j] @ self.p[k]
                R[k] = R[j] @ self.R[k]
            else:
                R[k], p[k] = R[k - 1], p[k - 1]
        return R, p
