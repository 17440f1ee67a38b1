"""Error-state EKF: the IMU propagates, visual odometry's relative poses correct (loosely coupled).

Nominal state: position ``p``, velocity ``v`` (world), attitude ``R`` (world from IMU), accelerometer and
gyro biases. Error state (15): ``dp, dv, dtheta, dba, dbg`` with the attitude error on the right,
``R_true = R Exp(dtheta)``. Visual odometry gives the camera's motion since the previous frame or since a
keyframe; the filter keeps a clone of the pose at that frame (stochastic cloning, 6 more error states), so a
relative measurement constrains the motion since then, not a drifting absolute pose. Also:

* gravity alignment and the gyro bias from the still first ``init_still_s`` seconds;
* zero-velocity updates where the IMU is quiet and odometry sees no motion;
* Mahalanobis gating of odometry (chi-square, 6 degrees of freedom), so gross errors are rejected;
* the camera-IMU extrinsics, the camera's time offset, and the IMU-antenna lever arm.

The world frame is gravity-aligned (z up) with its origin and heading at the IMU's start pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.rows import GrowingRows
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.imu import GRAVITY, ImuNoise, ImuSamples, RelativePoses, skew, so3_exp, so3_log

__all__ = ["EskfConfig", "ForwardFusion", "FusionResult", "fuse", "camera_to_imu_motion"]

P_, V_, TH_, BA_, BG_ = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
CP_, CTH_ = slice(15, 18), slice(18, 21)  # the clone's position and attitude errors


def _check_pose(T, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidDataError(f"{name} must be a finite 4 x 4 pose, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InvalidDataError(f"{name}: its 3 x 3 block is not a rotation")
    return T


@dataclass
class EskfConfig:
    """Settings of :func:`fuse`."""

    imu_noise: ImuNoise = field(default_factory=ImuNoise)
    imu_T_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    imu_T_antenna: np.ndarray = field(default_factory=lambda: np.eye(4))
    camera_time_offset_s: float = 0.0  #: IMU time of a frame = its camera stamp + this
    init_still_s: float = 1.0  #: the cart stands still this long at the start (gravity, gyro bias)
    gate_prob: float = 0.999  #: odometry with a larger Mahalanobis distance is rejected
    zupt: bool = True
    zupt_window_s: float = 0.25
    zupt_speed_m_s: float = 0.01  #: odometry speed under which the cart may be still
    zupt_sigma_m_s: float = 0.003
    sigma_accel_bias: float = 0.1  #: m/s^2, prior
    sigma_gyro_bias: float = 0.002  #: rad/s, prior beyond the still-start estimate
    vo_cov_scale: float = 1.0  #: multiplies odometry's covariance
    #: survey wheel (``fuse(..., wheel=...)``): its distance error per frame, as a share of the distance (slip,
    #: wheel size) and a floor (encoder resolution), in m
    wheel_sigma_frac: float = 0.01
    wheel_sigma_m: float = 0.001
    #: the ground is flat: the IMU stays at its start height within this (m), at every frame; None: not assumed
    flat_ground_sigma_m: float | None = None

    def __post_init__(self):
        self.imu_T_camera = _check_pose(self.imu_T_camera, "imu_T_camera")
        self.imu_T_antenna = _check_pose(self.imu_T_antenna, "imu_T_antenna")
        if not 0.0 < self.gate_prob < 1.0:
            raise InvalidDataError(f"gate_prob must lie in (0, 1), got {self.gate_prob!r}")
        for name in ("init_still_s", "zupt_window_s", "zupt_sigma_m_s", "sigma_accel_bias", "sigma_gyro_bias",
                     "vo_cov_scale", "flat_ground_sigma_m", "wheel_sigma_frac", "wheel_sigma_m"):
            v = getattr(self, name)
            if v is None and name == "flat_ground_sigma_m":
                continue
            if not v > 0:
                raise InvalidDataError(f"{name} must be positive, got {v!r}")


@dataclass
class FusionResult:
    """Fused IMU poses at every IMU sample, the pose covariance at every frame, and what was used."""

    t_s: np.ndarray
    p: np.ndarray
    v: np.ndarray
    R: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    frame_t_s: np.ndarray  #: IMU time of each odometry frame
    frame_cov: np.ndarray  #: (m, 6, 6) covariance of (dtheta, dp) after each frame's update
    frame_index: np.ndarray  #: IMU sample index of the first sample after each frame
    frame_p: np.ndarray  #: position at each frame, after its update
    frame_R: np.ndarray
    vo_used: np.ndarray  #: per frame: the relative pose was applied
    vo_rejected: np.ndarray  #: per frame: gated out
    zupt_t_s: np.ndarray  #: IMU times of the zero-velocity updates
    imu_T_antenna: np.ndarray

    @property
    def zupt_count(self) -> int:
        return int(self.zupt_t_s.size)

    def antenna_trajectory(self) -> Trajectory:
        """Antenna poses (world from antenna) at the IMU times, as a :class:`~gpr3d.core.trajectory.Trajectory`."""
        return _antenna(self.t_s, self.R, self.p, self.imu_T_antenna)


def _antenna(t_s, R_imu, p_imu, imu_T_antenna) -> Trajectory:
    Ta = imu_T_antenna
    R = R_imu @ Ta[:3, :3]
    p = p_imu + R_imu @ Ta[:3, 3]
    q = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    return Trajectory(t_s, p, q)


def camera_to_imu_motion(R_c, p_c, cov_c, imu_T_camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The IMU's motion between two frames from the camera's (``imu_T_camera`` fixed), with its covariance."""
    Rbc, pbc = imu_T_camera[:3, :3], imu_T_camera[:3, 3]
    R_b = Rbc @ R_c @ Rbc.T
    p_b = Rbc @ p_c + pbc - R_b @ pbc
    J = np.zeros((6, 6))
    J[:3, :3] = Rbc
    J[3:, :3] = R_b @ skew(pbc) @ Rbc
    J[3:, 3:] = Rbc
    return R_b, p_b, J @ cov_c @ J.T


class _Filter:
    """The filter proper. Its error state is right-invariant (Barrau and Bonnabel's invariant EKF on SE_2(3),
    with biases as in Hartley et al.): ``R_true = Exp(dtheta) R``, ``v_true = Exp(dtheta) v + dv``,
    ``p_true = Exp(dtheta) p + dp`` with ``dtheta`` in the world frame, and the same for the clone. The
    directions the data cannot see (a turn about gravity, a shift of the whole path) are then fixed vectors of
    the error state, not functions of the estimate, so an update cannot gain spurious information about them:
    the covariance stays consistent over long runs, where the body-frame (standard) error state becomes
    overconfident in heading and position."""

    def __init__(self, cfg: EskfConfig, R0, bg0):
        self.p, self.v, self.R = np.zeros(3), np.zeros(3), R0
        self.ba, self.bg = np.zeros(3), bg0
        self.P = np.zeros((21, 21))
        # position and heading define the frame (known exactly). The still start's roll and pitch err by the
        # accelerometer bias across gravity: tilt error (body frame) = [g_b]x ba / g^2, fully correlated with it
        sb = cfg.sigma_accel_bias
        g_b = R0.T @ np.array([0.0, 0.0, GRAVITY])
        M = skew(g_b) / GRAVITY**2
        Pb = np.diag([1e-8] * 3 + [1e-4] * 3 + [1e-8] * 3 + [sb**2] * 3 + [cfg.sigma_gyro_bias**2] * 3)
        Pb[TH_, TH_] += sb**2 * M @ M.T
        Pb[TH_, BA_] = sb**2 * M
        Pb[BA_, TH_] = Pb[TH_, BA_].T
        T = np.eye(15)
        T[TH_, TH_] = R0  # body-frame attitude error -> world frame
        self.P[:15, :15] = T @ Pb @ T.T
        self.clone()
        self.Phi = np.eye(15)
        self.nodes: list | None = None  #: a list to record smoother nodes in (see ``fuse(..., smooth=True)``)
        n = cfg.imu_noise
        self.q = np.array([n.accel_noise**2, n.gyro_noise**2, n.accel_bias_walk**2, n.gyro_bias_walk**2])
        self._g = skew([0.0, 0.0, -GRAVITY])

    def propagate(self, f_m, w_m, dt):
        f = f_m - self.ba
        w = w_m - self.bg
        R, v, p = self.R, self.v, self.p
        # error dynamics (continuous, at the step's start), then Phi = I + A dt + (A dt)^2 / 2
        sp, sv = -skew(p) @ R, -skew(v) @ R
        A = np.zeros((15, 15))
        A[P_, V_] = np.eye(3)
        A[P_, BG_] = sp
        A[V_, TH_] = self._g
        A[V_, BA_] = -R
        A[V_, BG_] = sv
        A[TH_, BG_] = -R
        Ad = A * dt
        F = np.eye(15) + Ad + 0.5 * Ad @ Ad
        # white noise of the gyro and accelerometer enters through the pose's adjoint
        G = np.zeros((15, 6))
        G[P_, :3] = sp
        G[V_, :3] = sv
        G[V_, 3:] = -R
        G[TH_, :3] = -R
        qa, qg, qba, qbg = self.q * dt
        Q = (G * np.array([qg, qg, qg, qa, qa, qa])) @ G.T  # G diag(q) G^T, the diagonal as column scales
        idx = np.arange(3)
        Q[9 + idx, 9 + idx] += qba
        Q[12 + idx, 12 + idx] += qbg
        # the nominal state: midpoint attitude for the specific force
        dR = so3_exp(w * dt)
        a = R @ so3_exp(0.5 * w * dt) @ f + np.array([0.0, 0.0, -GRAVITY])
        self.p = p + v * dt + 0.5 * a * dt * dt
        self.v = v + a * dt
        self.R = R @ dR
        self.Phi = F @ self.Phi
        P = self.P
        P[:15, :15] = F @ P[:15, :15] @ F.T + Q
        P[:15, 15:] = F @ P[:15, 15:]
        P[15:, :15] = P[:15, 15:].T
        self.P = 0.5 * (P + P.T)

    def state(self) -> tuple:
        return (self.p.copy(), self.v.copy(), self.R.copy(), self.ba.copy(), self.bg.copy(), self.pc.copy(),
                self.Rc.copy())

    def node_prior(self, t: float, i: int):
        """Before the updates at time ``t`` (IMU interval ``i``): the prediction and the transition since the last
        node, for the smoother."""
        if self.nodes is not None:
            self.nodes.append({"t": t, "i": i, "prior": self.state(), "P_prior": self.P.copy(), "Phi": self.Phi})
        self.Phi = np.eye(15)

    def node_posterior(self, clone_follows: bool, frame: bool):
        if self.nodes is not None:
            self.nodes[-1].update(post=self.state(), P_post=self.P.copy(), clone=clone_follows, frame=frame)

    def clone(self):
        self.pc, self.Rc = self.p.copy(), self.R.copy()
        core = np.r_[0:3, 6:9]
        P = self.P  # every clone row and column is overwritten: the core's, and its block
        P[15:, :15] = P[core, :15]
        P[:15, 15:] = P[:15, core]
        P[15:, 15:] = P[np.ix_(core, core)]

    def _correct(self, H, r, Rm, gate: float | None) -> bool:
        P = self.P
        S = H @ P @ H.T + Rm
        S = 0.5 * (S + S.T)
        try:
            Si = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            return False
        if gate is not None and float(r @ Si @ r) > gate:
            return False
        K = P @ H.T @ Si
        dx = K @ r
        IKH = np.eye(21) - K @ H
        P = IKH @ P @ IKH.T + K @ Rm @ K.T
        self.P = 0.5 * (P + P.T)  # round-off would otherwise build up an asymmetry the next gains amplify
        E = so3_exp(dx[TH_])
        self.R = E @ self.R
        self.v = E @ self.v + dx[V_]
        self.p = E @ self.p + dx[P_]
        self.ba = self.ba + dx[BA_]
        self.bg = self.bg + dx[BG_]
        Ec = so3_exp(dx[CTH_])
        self.Rc = Ec @ self.Rc
        self.pc = Ec @ self.pc + dx[CP_]
        return True

    def _h_position(self, rows: np.ndarray) -> np.ndarray:
        """Jacobian of ``rows @ Rc^T (p - pc)`` (the motion since the clone, in the clone's frame)."""
        A = rows @ self.Rc.T
        H = np.zeros((A.shape[0], 21))
        H[:, P_] = A
        H[:, CP_] = -A
        H[:, TH_] = -A @ skew(self.p)
        H[:, CTH_] = A @ skew(self.p)
        return H

    def update_relative(self, R_z, p_z, cov, gate: float) -> bool:
        dR = self.Rc.T @ self.R
        h_p = self.Rc.T @ (self.p - self.pc)
        r = np.concatenate([so3_log(dR.T @ R_z), p_z - h_p])
        H = np.zeros((6, 21))
        H[:3, TH_] = self.R.T
        H[:3, CTH_] = -self.R.T
        H[3:] = self._h_position(np.eye(3))
        return self._correct(H, r, cov, gate)

    def update_forward(self, distance_m: float, sigma_m: float) -> bool:
        """The survey wheel: the IMU's forward travel since the clone (along the clone's x axis) is ``distance_m``.

        The wheel is taken to run on the IMU's fore-aft line; over one frame the chord and the arc agree to
        second order in the turn."""
        h = self.Rc.T @ (self.p - self.pc)
        H = self._h_position(np.array([[1.0, 0.0, 0.0]]))
        return self._correct(H, np.array([distance_m - h[0]]), np.array([[sigma_m**2]]), float(chi2.ppf(0.999, 1)))

    def update_height(self, sigma_z: float):
        """A cart on flat ground: the IMU stays at its start height (0 in the filter's world)."""
        H = np.zeros((1, 21))
        H[0, 2] = 1.0
        H[0, TH_] = -skew(self.p)[2]
        self._correct(H, np.array([-self.p[2]]), np.array([[sigma_z**2]]), None)

    def update_still(self, sigma: float):
        H = np.zeros((3, 21))
        H[:, V_] = np.eye(3)
        H[:, TH_] = -skew(self.v)
        self._correct(H, -self.v, np.eye(3) * sigma**2, None)

    def pose_cov(self) -> np.ndarray:
        """Covariance of the pose in the usual (body-frame) convention: ``(Log(R^T R_true), p_true - p)``."""
        J = np.zeros((6, 6))
        J[:3, :3] = self.R.T
        J[3:, :3] = -skew(self.p)
        J[3:, 3:] = np.eye(3)
        idx = np.r_[6:9, 0:3]
        return J @ self.P[np.ix_(idx, idx)] @ J.T


def _minus(a: tuple, b: tuple) -> np.ndarray:
    """The right-invariant error ``a - b`` of two nominal states (21: p, v, theta, ba, bg, clone p, clone theta)."""
    th = so3_log(a[2] @ b[2].T)
    E = so3_exp(th)
    thc = so3_log(a[6] @ b[6].T)
    return np.concatenate([a[0] - E @ b[0], a[1] - E @ b[1], th, a[3] - b[3], a[4] - b[4],
                           a[5] - so3_exp(thc) @ b[5], thc])


def _plus(b: tuple, d: np.ndarray) -> tuple:
    E, Ec = so3_exp(d[TH_]), so3_exp(d[CTH_])
    return (E @ b[0] + d[P_], E @ b[1] + d[V_], E @ b[2], b[3] + d[BA_], b[4] + d[BG_], Ec @ b[5] + d[CP_], Ec @ b[6])


def _rts(nodes: list) -> tuple[list, list, list, list]:
    """Rauch-Tung-Striebel backwards over the filter's nodes (each update time): the smoothed states and
    covariances, and each node's correction from its posterior and from its prior."""
    n = len(nodes)
    xs, Ps = [None] * n, [None] * n
    eps, dlt = [np.zeros(21)] * n, [np.zeros(21)] * n
    xs[-1], Ps[-1] = nodes[-1]["post"], nodes[-1]["P_post"]
    dlt[-1] = _minus(xs[-1], nodes[-1]["prior"])
    for j in range(n - 2, -1, -1):
        a, b = nodes[j], nodes[j + 1]
        A = np.zeros((21, 21))
        A[:15, :15] = b["Phi"]
        if a["clone"]:  # the clone restarts at the pose of node j
            A[15:18, 0:3] = np.eye(3)
            A[18:21, 6:9] = np.eye(3)
        else:
            A[15:, 15:] = np.eye(6)
        # C = P+ A^T (P-)^-1, by least squares: P- is near singular right after a clone
        Ct = np.linalg.lstsq(b["P_prior"], A @ a["P_post"], rcond=1e-13)[0]
        C = Ct.T
        eps[j] = C @ _minus(xs[j + 1], b["prior"])
        xs[j] = _plus(a["post"], eps[j])
        P = a["P_post"] + C @ (Ps[j + 1] - b["P_prior"]) @ C.T
        Ps[j] = 0.5 * (P + P.T)
        dlt[j] = _minus(xs[j], a["prior"])
    return xs, Ps, eps, dlt


def _align(t_s, accel, gyro, still_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch from gravity, and the gyro bias, over the still first ``still_s`` seconds."""
    sel = t_s <= t_s[0] + still_s
    if sel.sum() < 10:
        raise InvalidDataError(f"gravity alignment needs at least 10 IMU samples in the first {still_s:g} s")
    f = accel[sel]
    spread = float(np.linalg.norm(f.std(0)))
    if spread > 0.5:
        raise InvalidDataError(f"the cart is not still in the first {still_s:g} s (accelerometer spread "
                               f"{spread:.2f} m/s^2): start the recording at rest, or lower init_still_s")
    u = f.mean(0) / np.linalg.norm(f.mean(0))
    pitch = np.arctan2(-u[0], np.hypot(u[1], u[2]))
    roll = np.arctan2(u[1], u[2])
    R0 = Rotation.from_euler("ZYX", [0.0, pitch, roll]).as_matrix()
    return R0, gyro[sel].mean(0)


class ForwardFusion:
    """The filter of :func:`fuse` run as the data come: IMU samples, odometry frames and survey wheel distances
    fed in chunks of any size, each stream in time order (:meth:`add_imu`, :meth:`add_frames`,
    :meth:`add_wheel`), and :meth:`run` between them. The filter moves on as far as what has come allows: past
    an IMU sample once every odometry frame up to it has come (a frame after it, or :meth:`end_frames`), a frame
    once the next frame has come (whether it refers to the same keyframe decides the clone), and the wheel's
    distance up to the frame. The poses at the IMU samples it has passed (:attr:`n_done`) are final: fed
    everything and finished, it gives what :func:`fuse` without smoothing gives, to the last bit.

    ``rate_hz``: the IMU's sample rate (the zero-velocity test's window and noise levels; :func:`fuse` gives the
    record's median rate). ``wheel``: survey wheel distances will come. ``nodes``: record the smoother's nodes
    (:func:`fuse`'s ``smooth``).
    """

    def __init__(self, cfg: EskfConfig | None = None, *, rate_hz: float, wheel: bool = False, nodes: bool = False):
        self.cfg = cfg = cfg or EskfConfig()
        if not (isinstance(rate_hz, (int, float, np.number)) and np.isfinite(rate_hz) and rate_hz > 0):
            raise InvalidDataError(f"rate_hz must be a positive IMU sample rate, got {rate_hz!r}")
        self.rate_hz = float(rate_hz)
        self.imu_t, self.accel, self.gyro = GrowingRows(), GrowingRows(3), GrowingRows(3)
        self.vo_t, self.vo_R, self.vo_p = GrowingRows(), GrowingRows(3, 3), GrowingRows(3)
        self.vo_cov, self.vo_valid, self.vo_ref = GrowingRows(6, 6), GrowingRows(dtype=bool), GrowingRows(dtype=int)
        self.wheel = (GrowingRows(), GrowingRows()) if wheel else None
        self.frames_ended = self.wheel_ended = self.imu_ended = False
        self.flt = None
        self._nodes = nodes
        self.gate = float(chi2.ppf(cfg.gate_prob, 6))
        self.win = max(3, int(round(cfg.zupt_window_s * self.rate_hz)))
        self.sa = cfg.imu_noise.accel_noise * np.sqrt(self.rate_hz)
        self.sg = cfg.imu_noise.gyro_noise * np.sqrt(self.rate_hz)
        self.out = {k: GrowingRows(*shape) for k, shape in (("p", (3,)), ("v", (3,)), ("R", (3, 3)), ("ba", (3,)),
                                                        ("bg", (3,)))}
        self.frame = {k: GrowingRows(*shape) for k, shape in (("t", ()), ("cov", (6, 6)), ("idx", ()), ("p", (3,)),
                                                          ("R", (3, 3)), ("used", ()), ("rejected", ()))}
        self.zupts: list = []
        self.vo_speed = np.inf
        self.clone_frame, self.clone_t = -1, None  # the frame (and its IMU time) the filter's clone was taken at
        self.since_key = (np.nan, np.zeros(3))  # (camera time, IMU motion from the live keyframe) of the last frame
        self.k = 0  # the next odometry frame to look at
        self.fi = 0  # odometry frames used so far (those within the IMU's span)
        self.i = 0  # the IMU interval [i, i + 1] the filter is in
        self.t_now = None

    @property
    def n_done(self) -> int:
        """The IMU samples whose poses are final."""
        return self.out["p"].n

    def add_imu(self, t_s, accel, gyro) -> None:
        """IMU samples: times (s, increasing, after those given before), specific forces (m/s^2) and angular
        rates (rad/s) in the IMU frame."""
        t = _rows(t_s, None, (), "IMU times")
        a, g = _rows(accel, t.size, (3,), "IMU forces"), _rows(gyro, t.size, (3,), "IMU rates")
        if not (np.isfinite(a).all() and np.isfinite(g).all()):
            raise InvalidDataError(f"IMU samples from {self.imu_t.n} on hold NaN/inf")
        _after(t, self.imu_t, "IMU")
        self.imu_t.append(t)
        self.accel.append(a)
        self.gyro.append(g)

    def add_frames(self, t_s, R, p, cov, valid=None, ref=None) -> None:
        """Odometry frames (as :class:`~gpr3d.core.inertial.RelativePoses`' entries, numbered on from those given
        before; ``ref`` by those numbers, default the frame before): a non-finite motion is a failed frame."""
        t = _rows(t_s, None, (), "visual odometry times")
        n, k = t.size, np.arange(self.vo_t.n, self.vo_t.n + t.size)
        R, p, cov = _rows(R, n, (3, 3), "visual odometry R"), _rows(p, n, (3,), "visual odometry p"), \
            _rows(cov, n, (6, 6), "visual odometry cov")
        valid = np.ones(n, bool) if valid is None else _rows(valid, n, (), "visual odometry valid").astype(bool)
        ref = k - 1 if ref is None else _rows(ref, n, (), "visual odometry ref").astype(int)
        _after(t, self.vo_t, "visual odometry")
        if np.any(ref >= k):
            raise InvalidDataError(f"visual odometry ref: frame {k[np.argmax(ref >= k)]} refers to itself or a "
                                   "later frame")
        ok = np.isfinite(R).all((1, 2)) & np.isfinite(p).all(1) & np.isfinite(cov).all((1, 2))
        self.vo_t.append(t)
        self.vo_R.append(R)
        self.vo_p.append(p)
        self.vo_cov.append(cov)
        self.vo_valid.append(valid & ok & (k > 0))
        self.vo_ref.append(ref)

    def add_wheel(self, t_s, distance_m) -> None:
        """Survey wheel readings: times (s on the IMU clock, increasing) and forward distances (m, not
        decreasing)."""
        if self.wheel is None:
            raise InvalidDataError("wheel readings for a fusion made without a wheel (wheel=True)")
        t = _rows(t_s, None, (), "wheel times")
        dist = _rows(distance_m, t.size, (), "wheel distances")
        if not np.isfinite(dist).all():
            raise InvalidDataError("wheel distances hold NaN/inf")
        _after(t, self.wheel[0], "wheel")
        if np.any(np.diff(np.r_[self.wheel[1][-1:], dist]) < -1e-9):
            raise InvalidDataError("wheel: the distance decreases; pass the wheel's forward count")
        self.wheel[0].append(t)
        self.wheel[1].append(dist)

    def end_frames(self) -> None:
        """No more odometry frames will come (none at all: call it first)."""
        self.frames_ended = True

    def end_wheel(self) -> None:
        """No more wheel readings will come: frames after the last one no longer wait for them (the wheel's
        distance is held at its last reading)."""
        self.wheel_ended = True

    def _start(self) -> bool:
        t = self.imu_t[:]
        if not t.size or (t[-1] <= t[0] + self.cfg.init_still_s and not self.imu_ended):
            return False  # (the still start's alignment needs all of its samples)
        if t[-1] < t[0] + self.cfg.init_still_s:
            raise InvalidDataError(f"the still start ({self.cfg.init_still_s:g} s: init_still_s, --still) is longer "
                                   f"than the IMU record ({t[-1] - t[0]:.3g} s)")
        g = float(np.median(np.linalg.norm(self.accel[:], axis=1)))
        if not 2.0 < g < 40.0:  # (m/s^2: at rest an IMU reads about 9.8; fuse's ImuSamples checks the same)
            hint = " (in g? multiply by 9.80665)" if 0.2 < g < 4 else ""
            raise InvalidDataError(f"IMU forces: median magnitude {g:.3g} is not in m/s^2{hint}")
        R0, bg0 = _align(t, self.accel[:], self.gyro[:], self.cfg.init_still_s)
        self.flt = _Filter(self.cfg, R0, bg0)
        if self._nodes:
            self.flt.nodes = []
        self.t_now = self.clone_t = t[0]
        self._record()
        return True

    def _record(self):
        f = self.flt
        for k, v in (("p", f.p), ("v", f.v), ("R", f.R), ("ba", f.ba), ("bg", f.bg)):
            self.out[k].append(v)

    def _step_to(self, t_target):
        dt = t_target - self.t_now
        if dt > 0:
            i, j = self.i, min(self.i + 1, self.imu_t.n - 1)
            self.flt.propagate(0.5 * (self.accel[i] + self.accel[j]), 0.5 * (self.gyro[i] + self.gyro[j]), dt)
            self.t_now = t_target

    def _frame_ready(self, k) -> bool:
        # the next frame's reference (the clone) and the wheel's distance up to this frame must be known
        if not (k + 1 < self.vo_t.n or self.frames_ended):
            return False
        if self.wheel is None or self.wheel_ended:
            return True
        wt = self.wheel[0]
        return wt.n > 0 and wt[-1] >= self.vo_t[k] + self.cfg.camera_time_offset_s

    def run(self) -> int:
        """Move the filter on as far as what has come allows; returns how many more IMU samples are final."""
        before = self.n_done
        if self.flt is None and not self._start():
            return 0
        cfg, flt, off = self.cfg, self.flt, self.cfg.camera_time_offset_s
        t0 = self.imu_t[0]
        while self.i + 1 < self.imu_t.n:
            i = self.i
            t_next = self.imu_t[i + 1]
            # the odometry frames up to t_next (those before the first IMU sample are not used)
            while self.k < self.vo_t.n and self.vo_t[self.k] + off <= t_next:
                k = self.k
                ftk = self.vo_t[k] + off
                if ftk < t0:
                    self.k += 1
                    continue
                if not self._frame_ready(k):
                    return self.n_done - before
                self._frame(k, ftk, i)
                self.k += 1
            if self.k >= self.vo_t.n and not self.frames_ended:
                return self.n_done - before  # (a frame before t_next may yet come)
            self._step_to(t_next)
            win = self.win
            if cfg.zupt and self.vo_speed < cfg.zupt_speed_m_s and i + 1 >= win:
                a = self.accel[i + 2 - win: i + 2]
                g = self.gyro[i + 2 - win: i + 2]
                if np.all(a.std(0) < 3 * self.sa) and np.all(g.std(0) < 3 * self.sg):
                    flt.node_prior(t_next, i)
                    flt.update_still(cfg.zupt_sigma_m_s)
                    flt.node_posterior(clone_follows=False, frame=False)
                    self.zupts.append(t_next)
            self._record()
            self.i += 1
        return self.n_done - before

    def _frame(self, k, ftk, i):
        cfg, flt = self.cfg, self.flt
        self._step_to(ftk)
        flt.node_prior(ftk, i)
        ref = self.vo_ref
        used = rejected = False
        if self.vo_valid[k] and self.fi > 0 and self.clone_frame == ref[k]:
            R_b, p_b, cov_b = camera_to_imu_motion(self.vo_R[k], self.vo_p[k], self.vo_cov[k] * cfg.vo_cov_scale,
                                                   cfg.imu_T_camera)
            used = flt.update_relative(R_b, p_b, cov_b, self.gate)
            rejected = not used
            if used:  # the speed over the last frame interval, through the keyframe's motion at the frame before
                # (a mean over a longer window lags where a still cart sets off: zero-velocity updates then
                # pull a moving cart to rest, and the covariance turns overconfident)
                t_j, p_j = self.since_key
                self.vo_speed = np.linalg.norm(p_b - p_j) / (self.vo_t[k] - t_j)
                self.since_key = (self.vo_t[k], p_b)
            else:
                self.vo_speed = np.inf
        else:
            self.vo_speed = np.inf
        # the filter's clone stays at the live keyframe: it moves on unless the next frame refers to that keyframe
        # too (frame to frame: always)
        reclone = k + 1 >= self.vo_t.n or ref[k + 1] != self.clone_frame
        if self.wheel is not None and self.fi > 0:
            d0, d1 = np.interp([self.clone_t, ftk], self.wheel[0][:], self.wheel[1][:])
            flt.update_forward(d1 - d0, cfg.wheel_sigma_frac * (d1 - d0) + cfg.wheel_sigma_m)
        if cfg.flat_ground_sigma_m is not None:
            flt.update_height(cfg.flat_ground_sigma_m)
        flt.node_posterior(clone_follows=reclone, frame=True)
        if reclone:
            flt.clone()
            self.clone_frame, self.clone_t = k, ftk
            self.since_key = (self.vo_t[k], np.zeros(3))
        fr = self.frame
        for key, v in (("t", ftk), ("cov", flt.pose_cov()), ("idx", i + 1), ("p", flt.p), ("R", flt.R),
                       ("used", used), ("rejected", rejected)):
            fr[key].append(v)
        self.fi += 1

    def antenna_at(self, t_s) -> Trajectory:
        """The antenna's poses at the times ``t_s`` (within the final samples' span), interpolated between the
        final poses about them (as :meth:`FusionResult.antenna_trajectory` then
        :meth:`~gpr3d.core.trajectory.Trajectory.at` give them)."""
        t_s = np.asarray(t_s, float).reshape(-1)
        n = self.n_done
        t = self.imu_t[:n]
        if not t_s.size or n < 2 or t_s.min() < t[0] or t_s.max() > t[-1]:
            span = f"{t[0]:.6f}..{t[-1]:.6f} s" if n else "none yet"
            raise InvalidDataError(f"poses asked for outside the final ones (their span: {span})")
        lo = min(max(int(np.searchsorted(t, t_s.min(), side="right")) - 1, 0), n - 2)
        hi = max(min(int(np.searchsorted(t, t_s.max(), side="left")) + 1, n), lo + 2)
        return _antenna(t[lo:hi], self.out["R"][lo:hi], self.out["p"][lo:hi], self.cfg.imu_T_antenna).at(t_s)

    def finish(self) -> FusionResult:
        """Every stream ended: the filter run to the last IMU sample (frames after it are not used); the result
        over every IMU sample."""
        self.frames_ended = self.wheel_ended = self.imu_ended = True
        if self.imu_t.n == 0:
            raise InvalidDataError("no IMU samples came")
        self.run()
        o, fr = self.out, self.frame
        return FusionResult(self.imu_t[:], o["p"][:], o["v"][:], o["R"][:], o["ba"][:], o["bg"][:], fr["t"][:],
                            fr["cov"][:], fr["idx"][:].astype(int), fr["p"][:], fr["R"][:], fr["used"][:].astype(bool),
                            fr["rejected"][:].astype(bool), np.asarray(self.zupts, dtype=float),
                            self.cfg.imu_T_antenna)


def _rows(x, n, shape: tuple, what: str) -> np.ndarray:
    """``x`` as floats of shape ``(n, *shape)`` (``n`` None: any number of rows, times: finite)."""
    a = np.asarray(x, float)
    if n is None:
        a = a.reshape(-1)
        if not np.isfinite(a).all():
            raise InvalidDataError(f"{what} hold NaN/inf")
    elif a.shape != (n, *shape):
        raise InvalidDataError(f"{what}: expected shape {(n, *shape)}, got {a.shape}")
    return a


def _after(t, before: GrowingRows, what: str) -> None:
    """``t`` increases, and after the times ``before`` holds."""
    full = np.r_[before[-1:], t]
    if np.any(np.diff(full) <= 0):
        k = int(np.argmax(np.diff(full) <= 0))
        raise InvalidDataError(f"{what}: timestamps must increase (at {full[k + 1]:.6f} s after {full[k]:.6f} s)")


def fuse(imu: ImuSamples, vo: RelativePoses | None, cfg: EskfConfig | None = None, *,
         wheel: tuple | None = None, smooth: bool = False) -> FusionResult:
    """Fuse IMU samples with visual odometry (or none: IMU alone) into poses at every IMU sample.

    Parameters
    ----------
    imu : ImuSamples
        The IMU's times, specific forces and angular rates (body frame).
    vo : RelativePoses or None
        Visual odometry: relative poses between camera frames on the IMU clock, with their covariances.
    cfg : EskfConfig, optional
        The filter's noise, initial state and extrinsics (default: :class:`EskfConfig` ()).
    wheel : tuple of (array_like, array_like), optional
        ``(t_s, distance_m)``, a survey wheel's forward distance on the IMU clock (non-decreasing); its travel
        between odometry frames is applied at every frame, through gaps in odometry too.
    smooth : bool
        After the filter's forward pass, a Rauch-Tung-Striebel pass backwards over every update (the
        fixed-interval smoother: each pose then rests on the data after it too, as offline GPR processing allows);
        the IMU-rate poses between updates take the corrections interpolated in time.

    Returns
    -------
    FusionResult
        Poses, velocities and biases at every IMU sample, and the covariance at every frame.

    Raises
    ------
    InvalidDataError
        A wheel record whose times and distances differ in length, are not increasing, hold NaN, or whose
        distance decreases.
    """
    ff = ForwardFusion(cfg, rate_hz=imu.rate_hz, wheel=wheel is not None, nodes=smooth)
    ff.add_imu(imu.t_s, imu.accel, imu.gyro)
    if vo is not None:
        ff.add_frames(vo.t_s, vo.R, vo.p, vo.cov, vo.valid, vo.ref)
    if wheel is not None:
        wt, wd = wheel
        if np.size(wt) < 2:
            raise InvalidDataError("wheel: two readings at least")
        ff.add_wheel(wt, wd)
    res = ff.finish()
    flt, n = ff.flt, imu.t_s.size
    out_p, out_v, out_R, out_ba, out_bg = res.p, res.v, res.R, res.accel_bias, res.gyro_bias
    f_p, f_R, f_cov = res.frame_p, res.frame_R, res.frame_cov
    if smooth and flt.nodes:
        xs, Ps, eps, dlt = _rts(flt.nodes)
        tn = np.array([nd["t"] for nd in flt.nodes])
        # the correction at each IMU sample: from the last node at or before it (its posterior's correction) to
        # the next node (its prior's), linear in time
        j = np.searchsorted(tn, imu.t_s, side="right") - 1
        for q in range(n):
            jj = j[q]
            if jj < 0:
                d = dlt[0]
            elif jj >= len(tn) - 1:
                d = eps[-1]
            else:
                w = (imu.t_s[q] - tn[jj]) / max(tn[jj + 1] - tn[jj], 1e-12)
                d = (1 - w) * eps[jj] + w * dlt[jj + 1]
            x = _plus((out_p[q], out_v[q], out_R[q], out_ba[q], out_bg[q], np.zeros(3), np.eye(3)), d)
            out_p[q], out_v[q], out_R[q], out_ba[q], out_bg[q] = x[:5]
        fnodes = [q for q, nd in enumerate(flt.nodes) if nd["frame"]]
        for fi_, q in enumerate(fnodes):
            x = xs[q]
            f_p[fi_], f_R[fi_] = x[0], x[2]
            J = np.zeros((6, 6))
            J[:3, :3] = x[2].T
            J[3:, :3] = -skew(x[0])
            J[3:, 3:] = np.eye(3)
            idx = np.r_[6:9, 0:3]
            f_cov[fi_] = J @ Ps[q][np.ix_(idx, idx)] @ J.T
    return res
