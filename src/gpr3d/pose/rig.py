"""A synthetic cart rig: random motion with turns and stops, an IMU and visual odometry, with exact truth.

The cart drives over gently uneven ground: its speed and turn rate follow smooth random profiles through
knots one second apart (monotone cubic pieces, so a stop is exactly still), its roll, pitch and height follow
the ground under it (functions of the distance travelled). Everything the IMU measures is analytic:
specific force ``R^T (a - g)`` and body rates from the Euler-angle rates, plus white noise and random-walk
biases (:class:`~gpr3d.pose.imu.ImuNoise`). Visual odometry is modelled, not rendered: the true camera
motion between frames with noise (a fraction of the step plus a floor, a rotation error per frame),
occasional outliers the odometry does not flag, and optional gaps in which tracking is lost.

>>> run = simulate_rig(RigConfig(duration_s=20), seed=1)              # doctest: +SKIP
>>> run.imu, run.vo, run.truth(run.imu.t_s)["p"]                       # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.interpolate import PchipInterpolator, make_interp_spline
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.imu import GRAVITY, ImuNoise, ImuSamples, RelativePoses, so3_exp, so3_log

__all__ = ["RigConfig", "RigRun", "simulate_rig", "default_imu_T_camera", "default_imu_T_antenna", "nees_runs"]


def _pose(R, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def default_imu_T_camera() -> np.ndarray:
    """A D435i-like mount: camera 0.25 m ahead of and 0.35 m above the IMU, looking forward and 40 deg down."""
    down = np.deg2rad(40.0)
    # camera axes (x right, y down, z forward) in the IMU frame (x forward, y left, z up), tilted down
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    tilt = so3_exp([0.0, down, 0.0])
    return _pose(tilt @ base, [0.25, 0.0, 0.35])


def default_imu_T_antenna() -> np.ndarray:
    """The antenna 0.3 m behind and 0.2 m below the IMU, axes aligned."""
    return _pose(np.eye(3), [-0.3, 0.0, -0.2])


@dataclass
class RigConfig:
    """What :func:`simulate_rig` makes (defaults: a 90 s run of about 25 m with three stops)."""

    duration_s: float = 90.0
    imu_rate_hz: float = 200.0
    camera_rate_hz: float = 15.0
    speed_m_s: tuple = (0.2, 0.6)
    turn_rate_rad_s: float = 0.5
    stops: int = 3  #: stops of 2-4 s besides the still start and end
    still_start_s: float = 3.0
    still_end_s: float = 2.0
    tilt_deg: float = 1.5  #: roll and pitch of the uneven ground
    bump_m: float = 0.01  #: height of the uneven ground
    imu_noise: ImuNoise = field(default_factory=ImuNoise)
    accel_bias_sigma: float = 0.05  #: m/s^2, each axis, at switch-on
    gyro_bias_sigma: float = 0.003  #: rad/s
    vo_trans_frac: float = 0.01  #: translation error per frame, as a fraction of the step
    vo_trans_floor_m: float = 5e-4
    vo_rot_deg: float = 0.03  #: rotation error per frame (each axis)
    vo_outlier_rate: float = 0.01  #: share of frames with a gross error that odometry does not flag
    vo_gap: tuple | None = None  #: (start_s, length_s) of lost tracking
    #: odometry against keyframes: a frame becomes the keyframe when it lies this far (m) or ``vo_keyframe_deg``
    #: from the last one; None: frame to frame. Each motion's noise follows its length (from the keyframe)
    vo_keyframe_m: float | None = None
    vo_keyframe_deg: float = 5.0
    #: ((x0, x1), (y0, y1)): the cart wanders over this patch (steering to random waypoints in it) instead of
    #: turning at random; it starts near the patch's centre
    area: tuple | None = None
    camera_time_offset_s: float = 0.005  #: IMU time of a frame = its camera stamp + this
    imu_T_camera: np.ndarray = field(default_factory=default_imu_T_camera)
    imu_T_antenna: np.ndarray = field(default_factory=default_imu_T_antenna)

    def __post_init__(self):
        if not self.duration_s >= self.still_start_s + self.still_end_s + 5:
            raise InvalidDataError(f"duration_s must leave at least 5 s of motion, got {self.duration_s!r}")
        for name in ("imu_rate_hz", "camera_rate_hz"):
            if not getattr(self, name) > 0:
                raise InvalidDataError(f"{name} must be positive, got {getattr(self, name)!r}")
        if self.camera_rate_hz > self.imu_rate_hz:
            raise InvalidDataError("camera_rate_hz must not exceed imu_rate_hz")
        if self.vo_keyframe_m is not None and not self.vo_keyframe_m > 0:
            raise InvalidDataError(f"vo_keyframe_m must be positive or None, got {self.vo_keyframe_m!r}")
        if not self.vo_keyframe_deg > 0:
            raise InvalidDataError(f"vo_keyframe_deg must be positive, got {self.vo_keyframe_deg!r}")


class _Motion:
    """The cart's true motion: analytic speed, heading, ground tilt and height; x, y integrated finely."""

    def __init__(self, cfg: RigConfig, rng: np.random.Generator):
        T = cfg.duration_s
        knots = np.arange(0.0, T + 1.0, 1.0)
        speed = rng.uniform(*cfg.speed_m_s, knots.size)
        turn = rng.uniform(-cfg.turn_rate_rad_s, cfg.turn_rate_rad_s, knots.size)
        still = (knots <= cfg.still_start_s) | (knots >= T - cfg.still_end_s)
        free = np.nonzero(~still)[0]
        for _ in range(cfg.stops):
            k0 = int(rng.choice(free[2:-5])) if free.size > 8 else None
            if k0 is not None:
                still[k0 : k0 + int(rng.integers(2, 5))] = True
        speed[still], turn[still] = 0.0, 0.0
        self.speed = PchipInterpolator(knots, speed)
        self.dspeed = self.speed.derivative()
        self.dist = self.speed.antiderivative()
        self.yaw0 = float(rng.uniform(-np.pi, np.pi))
        start = rng.uniform(-5, 5, 2)
        if cfg.area is None:
            self.turn = PchipInterpolator(knots, turn)
        else:
            start, turn = self._steer(cfg, knots, still, rng)
            self.turn = make_interp_spline(knots, turn, k=1)  # linear: each second is integrated as planned
        self.heading = self.turn.antiderivative()
        self.ground = {k: (a, 2 * np.pi / rng.uniform(1.3, 3.0), rng.uniform(0, 2 * np.pi))
                       for k, a in (("roll", np.deg2rad(cfg.tilt_deg)), ("pitch", np.deg2rad(cfg.tilt_deg)),
                                    ("z", cfg.bump_m))}
        self.grid = np.linspace(0.0, T, int(T * 2000) + 1)
        psi = self.yaw(self.grid)
        s = self.speed(self.grid)
        self.x = cumulative_trapezoid(s * np.cos(psi), self.grid, initial=0.0) + start[0]
        self.y = cumulative_trapezoid(s * np.sin(psi), self.grid, initial=0.0) + start[1]

    def _steer(self, cfg: RigConfig, knots, still, rng):
        """Turn rates at the knots that steer the cart to random waypoints inside ``cfg.area``, second by second,
        each second integrated on the same fine grid as the final path (so the plan is the path)."""
        (x0, x1), (y0, y1) = cfg.area
        if not (x1 - x0 > 0.5 and y1 - y0 > 0.5):
            raise InvalidDataError(f"area must be at least 0.5 m x 0.5 m, got {cfg.area!r}")
        margin = 0.15 * min(x1 - x0, y1 - y0)

        def waypoint():
            return rng.uniform([x0 + margin, y0 + margin], [x1 - margin, y1 - margin])

        xy = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)]) + rng.uniform(-0.1, 0.1, 2) * (x1 - x0)
        start, psi, wp = xy.copy(), self.yaw0, waypoint()
        turn = np.zeros(knots.size)
        for k in range(knots.size - 1):
            if not still[k + 1]:
                err = np.angle(np.exp(1j * (np.arctan2(wp[1] - xy[1], wp[0] - xy[0]) - psi)))
                turn[k + 1] = np.clip(1.5 * err, -cfg.turn_rate_rad_s, cfg.turn_rate_rad_s)
            tt = np.linspace(knots[k], knots[k + 1], 2001)
            ps = psi + cumulative_trapezoid(turn[k] + (turn[k + 1] - turn[k]) * (tt - knots[k]), tt, initial=0.0)
            sp = self.speed(tt)
            xy = xy + [np.trapezoid(sp * np.cos(ps), tt), np.trapezoid(sp * np.sin(ps), tt)]
            psi = ps[-1]
            if np.hypot(*(wp - xy)) < 0.4:
                wp = waypoint()
        return start, turn

    def yaw(self, t):
        return self.yaw0 + self.heading(t)

    def _ground(self, key, t):
        """Value, rate and second derivative of a ground-following quantity at times ``t``."""
        a, k, ph = self.ground[key]
        d, s, ds = self.dist(t), self.speed(t), self.dspeed(t)
        th = k * d + ph
        return a * np.sin(th), a * k * np.cos(th) * s, -a * k * k * np.sin(th) * s * s + a * k * np.cos(th) * ds

    def __call__(self, t) -> dict:
        t = np.asarray(t, dtype=float)
        psi, r, s, ds = self.yaw(t), self.turn(t), self.speed(t), self.dspeed(t)
        roll, droll, _ = self._ground("roll", t)
        pitch, dpitch, _ = self._ground("pitch", t)
        z, dz, ddz = self._ground("z", t)
        c, sn = np.cos(psi), np.sin(psi)
        p = np.stack([np.interp(t, self.grid, self.x), np.interp(t, self.grid, self.y), z], -1)
        v = np.stack([s * c, s * sn, dz], -1)
        a = np.stack([ds * c - s * r * sn, ds * sn + s * r * c, ddz], -1)
        cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
        w = np.stack([droll - r * sp, dpitch * cr + r * cp * sr, -dpitch * sr + r * cp * cr], -1)
        Rz = np.zeros(t.shape + (3, 3))
        Rz[..., 0, 0], Rz[..., 0, 1], Rz[..., 1, 0], Rz[..., 1, 1], Rz[..., 2, 2] = c, -sn, sn, c, 1.0
        Ry = np.zeros_like(Rz)
        Ry[..., 0, 0], Ry[..., 0, 2], Ry[..., 1, 1], Ry[..., 2, 0], Ry[..., 2, 2] = cp, sp, 1.0, -sp, cp
        Rx = np.zeros_like(Rz)
        Rx[..., 0, 0], Rx[..., 1, 1], Rx[..., 1, 2], Rx[..., 2, 1], Rx[..., 2, 2] = 1.0, cr, -sr, sr, cr
        return {"p": p, "v": v, "a": a, "R": Rz @ Ry @ Rx, "w": w, "speed": s}


@dataclass
class RigRun:
    """One synthetic run: the sensors' outputs and the truth (``truth(t)`` gives the IMU's p, v, a, R, w)."""

    config: RigConfig
    imu: ImuSamples
    vo: RelativePoses
    truth: _Motion
    accel_bias: np.ndarray  #: true biases at the IMU samples
    gyro_bias: np.ndarray
    vo_outliers: np.ndarray  #: frames given a gross error

    @property
    def path_length_m(self) -> float:
        return float(self.truth.dist(self.config.duration_s) - self.truth.dist(0.0))

    def antenna_truth(self, t) -> tuple[np.ndarray, np.ndarray]:
        """True antenna rotation and position at IMU times ``t``."""
        g = self.truth(t)
        Ta = self.config.imu_T_antenna
        return g["R"] @ Ta[:3, :3], g["p"] + g["R"] @ Ta[:3, 3]

    def truth_trajectory(self, t=None) -> Trajectory:
        """The true antenna poses at IMU times ``t`` (default: every IMU sample)."""
        t = self.imu.t_s if t is None else np.asarray(t, float)
        R, p = self.antenna_truth(t)
        return Trajectory(t, p, Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]])

    def wheel(self, *, scale_error: float = 0.005, tick_m: float = 0.001, rate_hz: float = 100.0):
        """A survey wheel on the IMU's fore-aft line: its forward distance ``(t_s, distance_m)``, read at
        ``rate_hz``, ``scale_error`` too long or short (wheel size, tyre), counted in ticks of ``tick_m``."""
        t = np.arange(0.0, self.config.duration_s + 1e-9, 1.0 / rate_hz)
        d = (self.truth.dist(t) - self.truth.dist(0.0)) * (1.0 + scale_error)
        return t, np.floor(d / tick_m) * tick_m

    def truth_in_filter_frame(self, t) -> tuple[np.ndarray, np.ndarray]:
        """The IMU's true rotations and positions at ``t`` as the filter's world sees them: origin at the start
        pose, the start heading removed (gravity-aligned, as :func:`gpr3d.pose.eskf.fuse` sets its world)."""
        g = self.truth(np.asarray(t, float))
        g0 = self.truth(np.array([self.imu.t_s[0]]))
        R0 = g0["R"][0]
        Rz = so3_exp([0.0, 0.0, -np.arctan2(R0[1, 0], R0[0, 0])])
        return Rz @ g["R"], (g["p"] - g0["p"][0]) @ Rz.T

    def to_world(self, traj: Trajectory) -> Trajectory:
        """A trajectory in the filter's world (origin and heading at the IMU's start, as
        :func:`gpr3d.pose.eskf.fuse` sets it) carried into the rig's world by the true start pose: the start
        a surveyor marks on site, so that estimated and true poses share the site frame."""
        g0 = self.truth(np.array([self.imu.t_s[0]]))
        R0 = g0["R"][0]
        Rz = so3_exp([0.0, 0.0, np.arctan2(R0[1, 0], R0[0, 0])])
        R = Rz @ Rotation.from_quat(traj.orientations_quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()
        return Trajectory(traj.timestamps_s, traj.positions_xyz @ Rz.T + g0["p"][0],
                          Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]])

    def loop_closures(self, frame_t_s, *, every_s: float = 1.0, radius_m: float = 0.4, max_angle_deg: float = 45.0,
                      min_gap_s: float = 15.0, sigma_m: float = 0.003, sigma_deg: float = 0.1,
                      outlier_rate: float = 0.0, seed: int = 0) -> list:
        """Loop closures as a camera would measure them (modelled, with exact truth): frames ``every_s`` apart
        whose views of the ground (0.8 m ahead of the IMU) lie within ``radius_m`` and headings within
        ``max_angle_deg`` of an earlier one at least ``min_gap_s`` before give the true relative pose with noise
        (``sigma_m`` each axis, ``sigma_deg``); ``outlier_rate`` of them are wrong by 0.2-1 m and 5-20 deg.
        ``frame_t_s``: the frames' IMU times (a ``FusionResult``'s ``frame_t_s``; the indices refer to it)."""
        from gpr3d.pose.graph import LoopClosure, revisits

        t = np.asarray(frame_t_s, dtype=float)
        rng = np.random.default_rng(np.random.SeedSequence([seed, 31]))
        g = self.truth(t)
        out = []
        for a, b in revisits(t, g["p"], g["R"], every_s=every_s, radius_m=radius_m, max_angle_deg=max_angle_deg,
                             min_gap_s=min_gap_s):
            Ri, pi, Rj, pj = g["R"][a], g["p"][a], g["R"][b], g["p"][b]
            R = Ri.T @ Rj @ so3_exp(rng.normal(0, np.deg2rad(sigma_deg), 3))
            p = Ri.T @ (pj - pi) + rng.normal(0, sigma_m, 3)
            if rng.random() < outlier_rate:
                u = rng.normal(size=3)
                u[2] = 0.0
                p = p + rng.uniform(0.2, 1.0) * u / np.linalg.norm(u)
                R = R @ so3_exp([0.0, 0.0, np.deg2rad(rng.uniform(5, 20)) * rng.choice([-1, 1])])
            out.append(LoopClosure(a, b, R, p, sigma_m, np.deg2rad(sigma_deg)))
        return out

    def filter_config(self, **kw):
        """The :class:`~gpr3d.pose.eskf.EskfConfig` that matches the rig's mounts, latency and still start."""
        from gpr3d.pose.eskf import EskfConfig

        c = self.config
        kw.setdefault("init_still_s", min(2.0, c.still_start_s))
        return EskfConfig(imu_T_camera=c.imu_T_camera, imu_T_antenna=c.imu_T_antenna,
                          camera_time_offset_s=c.camera_time_offset_s, **kw)

    def vo_trajectory(self) -> Trajectory:
        """Odometry alone: the chained camera motions carried to the antenna, at the frames' IMU times (in the
        first camera frame; compare after an alignment)."""
        Rc, pc = self.vo.chained()
        Tca = np.linalg.inv(self.config.imu_T_camera) @ self.config.imu_T_antenna
        t = self.vo.t_s + self.config.camera_time_offset_s
        return Trajectory(t, pc + Rc @ Tca[:3, 3], Rotation.from_matrix(Rc @ Tca[:3, :3]).as_quat()[:, [3, 0, 1, 2]])


def simulate_rig(cfg: RigConfig | None = None, seed: int = 0, *, motion_seed: int | None = None) -> RigRun:
    """A run of the synthetic rig; ``motion_seed`` (default ``seed``) fixes the path, ``seed`` the sensor noise."""
    cfg = cfg or RigConfig()
    motion = _Motion(cfg, np.random.default_rng(np.random.SeedSequence([seed if motion_seed is None else motion_seed,
                                                                         11])))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 12]))
    n = cfg.imu_noise
    dt = 1.0 / cfg.imu_rate_hz
    t = np.arange(0.0, cfg.duration_s + 0.5 * dt, dt)
    g = motion(t)
    f_true = np.einsum("nji,nj->ni", g["R"], g["a"] + np.array([0.0, 0.0, GRAVITY]))
    ba = rng.normal(0, cfg.accel_bias_sigma, 3) + np.cumsum(rng.normal(0, n.accel_bias_walk * np.sqrt(dt),
                                                                       (t.size, 3)), 0)
    bg = rng.normal(0, cfg.gyro_bias_sigma, 3) + np.cumsum(rng.normal(0, n.gyro_bias_walk * np.sqrt(dt),
                                                                      (t.size, 3)), 0)
    accel = f_true + ba + rng.normal(0, n.accel_noise / np.sqrt(dt), (t.size, 3))
    gyro = g["w"] + bg + rng.normal(0, n.gyro_noise / np.sqrt(dt), (t.size, 3))
    imu = ImuSamples(t, accel, gyro)

    tc = np.arange(0.0, cfg.duration_s - cfg.camera_time_offset_s - 1e-9, 1.0 / cfg.camera_rate_hz)
    tau = tc + cfg.camera_time_offset_s  # IMU time of each frame
    gc = motion(tau)
    Tbc = cfg.imu_T_camera
    Rc = gc["R"] @ Tbc[:3, :3]
    pc = gc["p"] + gc["R"] @ Tbc[:3, 3]
    m = tc.size
    R_rel = np.tile(np.eye(3), (m, 1, 1))
    p_rel = np.zeros((m, 3))
    cov = np.tile(np.eye(6), (m, 1, 1))
    valid = np.ones(m, bool)
    lost = np.zeros(m, bool)
    if cfg.vo_gap is not None:
        g0, gl = cfg.vo_gap
        lost = (tau >= g0) & (tau < g0 + gl)
        after = np.nonzero(tau >= g0 + gl)[0]
        valid[lost] = False
        if after.size:
            valid[after[0]] = False  # the motion into the first frame after the gap is unknown too
    outliers = np.zeros(m, bool)
    ref = np.arange(m) - 1
    key = 0
    sr = np.deg2rad(cfg.vo_rot_deg)
    for k in range(1, m):
        ref[k] = key
        Rt = Rc[key].T @ Rc[k]
        pt = Rc[key].T @ (pc[k] - pc[key])
        st = cfg.vo_trans_frac * np.linalg.norm(pt) + cfg.vo_trans_floor_m
        R_rel[k] = Rt @ so3_exp(rng.normal(0, sr, 3))
        p_rel[k] = pt + rng.normal(0, st, 3)
        cov[k] = np.diag([sr**2] * 3 + [st**2] * 3)
        if rng.random() < cfg.vo_outlier_rate:
            outliers[k] = True
            u = rng.normal(size=3)
            p_rel[k] += rng.uniform(0.05, 0.2) * u / np.linalg.norm(u)
            R_rel[k] = R_rel[k] @ so3_exp(np.deg2rad(rng.uniform(2, 5)) * rng.normal(size=3) / np.sqrt(3))
        # a new keyframe when the view has moved on (every frame without keyframes), or when tracking is lost
        if (cfg.vo_keyframe_m is None or lost[k] or np.linalg.norm(pt) > cfg.vo_keyframe_m
                or np.linalg.norm(so3_log(Rt)) > np.deg2rad(cfg.vo_keyframe_deg)):
            key = k
    outliers &= valid
    vo = RelativePoses(tc, R_rel, p_rel, cov, valid, ref)
    return RigRun(cfg, imu, vo, motion, ba, bg, outliers)


def nees_runs(cfg: RigConfig, runs: int, *, motion_seed: int = 7, first_seed: int = 100) -> np.ndarray:
    """Pose NEES at every frame of ``runs`` noise draws on one path (``motion_seed``): shape ``(runs, frames)``."""
    from gpr3d.pose.eskf import fuse
    from gpr3d.pose.metrics import nees

    out = []
    for s in range(runs):
        run = simulate_rig(cfg, seed=first_seed + s, motion_seed=motion_seed)
        res = fuse(run.imu, run.vo, run.filter_config())
        R_t, p_t = run.truth_in_filter_frame(res.frame_t_s)
        out.append(nees(res.frame_R, res.frame_p, res.frame_cov, R_t, p_t))
    return np.asarray(out)
