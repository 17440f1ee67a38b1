"""The synthetic rig by hand: its truth is physically consistent (velocity, acceleration and body rates are the
derivatives of position and attitude, taken numerically here), its IMU measures specific force and body rates with
the noise figures it is given, its odometry gives the camera's true relative motion with the stated noise, its
keyframes and gaps follow their rules, and its helpers (mounts, antenna truth, wheel, frames, loop closures) give
what a hand computation gives.
"""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.imu import GRAVITY, ImuNoise, so3_log
from gpr3d.pose.rig import RigConfig, default_imu_T_antenna, default_imu_T_camera, nees_runs, simulate_rig

QUIET = ImuNoise(1e-15, 1e-15, 1e-15, 1e-15)
EXACT = dict(imu_noise=QUIET, accel_bias_sigma=0.0, gyro_bias_sigma=0.0, vo_trans_frac=0.0, vo_trans_floor_m=0.0,
             vo_rot_deg=0.0, vo_outlier_rate=0.0)


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


@pytest.fixture
def exact_run():  # made in each test: a module-wide one would hide simulate_rig from the mutation runs
    return simulate_rig(RigConfig(duration_s=12.0, still_start_s=2.0, still_end_s=1.0, stops=1, turn_rate_rad_s=0.8,
                                  tilt_deg=3.0, bump_m=0.02, **EXACT), seed=3)


def test_velocity_acceleration_and_body_rates_are_the_derivatives_of_the_motion(exact_run):
    truth = exact_run.truth
    h = 1e-4
    for t in (2.5, 4.1, 6.77, 9.3):
        g, gp, gm = truth(np.array([t])), truth(np.array([t + h])), truth(np.array([t - h]))
        np.testing.assert_allclose(g["v"][0], (gp["p"][0] - gm["p"][0]) / (2 * h), rtol=0, atol=2e-5)
        np.testing.assert_allclose(g["a"][0], (gp["v"][0] - gm["v"][0]) / (2 * h), rtol=0, atol=2e-5)
        dR = (gp["R"][0] - gm["R"][0]) / (2 * h)
        W = g["R"][0].T @ dR  # the body rates' skew matrix
        np.testing.assert_allclose(g["w"][0], [W[2, 1], W[0, 2], W[1, 0]], rtol=0, atol=2e-6)
        np.testing.assert_allclose(W + W.T, 0, atol=1e-6)
        # the heading turns at the turn rate; the speed is the horizontal velocity's length
        assert g["speed"][0] == pytest.approx(np.hypot(*g["v"][0][:2]), rel=1e-12)
        yaw = lambda R: math.atan2(R[1, 0], R[0, 0])  # noqa: E731
        assert (yaw(gp["R"][0]) - yaw(gm["R"][0])) / (2 * h) == pytest.approx(float(truth.turn(t)), abs=1e-5)
        # roll, pitch and height follow the ground: within the settings
        assert abs(g["p"][0][2]) <= 0.02 + 1e-12
        rpy = Rotation.from_matrix(g["R"][0]).as_euler("ZYX")
        assert abs(rpy[1]) <= math.radians(3.0) + 1e-9 and abs(rpy[2]) <= math.radians(3.0) + 1e-9


def test_the_cart_stands_still_at_the_start_and_the_end(exact_run):
    truth = exact_run.truth
    t = np.linspace(0.0, 2.0, 9)
    g = truth(t)
    np.testing.assert_array_equal(g["speed"], 0.0)
    np.testing.assert_allclose(g["p"], np.repeat(g["p"][:1], 9, axis=0), atol=1e-12)
    np.testing.assert_allclose(g["w"], 0.0, atol=1e-12)
    g = truth(np.linspace(11.0, 12.0, 5))
    np.testing.assert_array_equal(g["speed"], 0.0)
    assert truth(np.array([5.0]))["speed"][0] > 0
    # the speed stays within its range where the cart drives (monotone pieces: no overshoot)
    s = truth(np.linspace(0.0, 12.0, 2401))["speed"]
    assert s.min() >= -1e-12 and s.max() <= 0.6 + 1e-12
    assert exact_run.path_length_m == pytest.approx(float(np.trapezoid(s, np.linspace(0.0, 12.0, 2401))), rel=1e-4)


def test_the_imu_measures_specific_force_and_body_rates(exact_run):
    run, truth = exact_run, exact_run.truth
    g = truth(run.imu.t_s)
    f = np.einsum("nji,nj->ni", g["R"], g["a"] + [0.0, 0.0, GRAVITY])
    np.testing.assert_allclose(run.imu.accel, f, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.imu.gyro, g["w"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.diff(run.imu.t_s), 1 / 200, rtol=1e-9)
    assert run.imu.t_s[0] == 0.0 and run.imu.t_s[-1] == pytest.approx(12.0, abs=1e-9)
    # standing still, it reads gravity alone
    assert np.linalg.norm(run.imu.accel[0]) == pytest.approx(GRAVITY, rel=1e-12)


def test_the_imu_noise_and_biases_have_the_stated_sizes():
    noise = ImuNoise(accel_noise=0.002, gyro_noise=1e-3, accel_bias_walk=0.01, gyro_bias_walk=5e-4)
    cfg = RigConfig(duration_s=40.0, imu_noise=noise, accel_bias_sigma=0.3, gyro_bias_sigma=0.02, imu_rate_hz=400.0)
    run = simulate_rig(cfg, seed=4)
    g = run.truth(run.imu.t_s)
    f = np.einsum("nji,nj->ni", g["R"], g["a"] + [0.0, 0.0, GRAVITY])
    dt = 1 / 400
    white_a = run.imu.accel - f - run.accel_bias
    white_g = run.imu.gyro - g["w"] - run.gyro_bias
    assert np.std(white_a) == pytest.approx(0.002 / math.sqrt(dt), rel=0.03)
    assert np.std(white_g) == pytest.approx(1e-3 / math.sqrt(dt), rel=0.03)
    assert np.std(np.diff(run.accel_bias, axis=0)) == pytest.approx(0.01 * math.sqrt(dt), rel=0.03)
    assert np.std(np.diff(run.gyro_bias, axis=0)) == pytest.approx(5e-4 * math.sqrt(dt), rel=0.03)
    # the switch-on biases: over many seeds, their spread is the stated sigma
    starts = np.array([simulate_rig(RigConfig(duration_s=8.0, still_start_s=1.0, still_end_s=1.0,
                                              accel_bias_sigma=0.3, gyro_bias_sigma=0.02, imu_rate_hz=20.0,
                                              camera_rate_hz=5.0), seed=s).accel_bias[0] for s in range(60)])
    assert np.std(starts) == pytest.approx(0.3, rel=0.15) and abs(np.mean(starts)) < 0.1


def test_odometry_gives_the_camera_s_true_motion(exact_run):
    run, cfg = exact_run, exact_run.config
    tc = run.vo.t_s
    np.testing.assert_allclose(tc, np.arange(tc.size) / 15.0, rtol=0, atol=1e-12)
    assert tc[-1] < 12.0 - 0.005 <= tc[-1] + 1 / 15.0
    g = run.truth(tc + 0.005)
    Tbc = cfg.imu_T_camera
    Rc = g["R"] @ Tbc[:3, :3]
    pc = g["p"] + np.einsum("nij,j->ni", g["R"], Tbc[:3, 3])
    np.testing.assert_array_equal(run.vo.ref, np.arange(tc.size) - 1)  # frame to frame
    for k in (1, 40, 97, tc.size - 1):
        np.testing.assert_allclose(run.vo.R[k], Rc[k - 1].T @ Rc[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(run.vo.p[k], Rc[k - 1].T @ (pc[k] - pc[k - 1]), rtol=0, atol=1e-12)
    assert run.vo.valid[1:].all() and not run.vo_outliers.any()  # (entry 0 is unused)
    # chained, the motions are the camera's poses in the first camera frame
    Rch, pch = run.vo.chained()
    np.testing.assert_allclose(pch[-1], Rc[0].T @ (pc[-1] - pc[0]), atol=1e-9)
    # and odometry alone carried to the antenna is the antenna's truth in the first camera frame
    traj = run.vo_trajectory()
    Tca = np.linalg.inv(Tbc) @ cfg.imu_T_antenna
    Ra, pa = run.antenna_truth(tc + 0.005)
    np.testing.assert_allclose(traj.timestamps_s, tc + 0.005, rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.positions_xyz, (pa - pc[0]) @ Rc[0], atol=1e-9)
    q = Rotation.from_matrix(np.einsum("ji,njk->nik", Rc[0], Ra)).as_quat()[:, [3, 0, 1, 2]]
    assert np.allclose(np.abs(np.sum(q * traj.orientations_quat_wxyz, axis=1)), 1.0, atol=1e-9)
    assert np.allclose(Tca[:3, 3], Tbc[:3, :3].T @ (cfg.imu_T_antenna[:3, 3] - Tbc[:3, 3]))


def test_odometry_noise_has_the_stated_size():
    cfg = RigConfig(duration_s=60.0, vo_trans_frac=0.05, vo_trans_floor_m=2e-3, vo_rot_deg=0.5, vo_outlier_rate=0.0)
    run = simulate_rig(cfg, seed=6)
    g = run.truth(run.vo.t_s + cfg.camera_time_offset_s)
    Rc = g["R"] @ cfg.imu_T_camera[:3, :3]
    pc = g["p"] + np.einsum("nij,j->ni", g["R"], cfg.imu_T_camera[:3, 3])
    z, rot = [], []
    for k in range(1, run.vo.t_s.size):
        pt = Rc[k - 1].T @ (pc[k] - pc[k - 1])
        st = 0.05 * np.linalg.norm(pt) + 2e-3
        z.append((run.vo.p[k] - pt) / st)
        rot.append(so3_log((Rc[k - 1].T @ Rc[k]).T @ run.vo.R[k]))
        np.testing.assert_allclose(run.vo.cov[k], np.diag([math.radians(0.5) ** 2] * 3 + [st ** 2] * 3), rtol=1e-12)
    assert np.std(z) == pytest.approx(1.0, rel=0.05) and abs(np.mean(z)) < 0.05
    assert np.std(rot) == pytest.approx(math.radians(0.5), rel=0.05)


def test_outliers_are_gross_and_unflagged():
    cfg = RigConfig(duration_s=30.0, vo_outlier_rate=0.2, **{k: v for k, v in EXACT.items() if k != "vo_outlier_rate"})
    run = simulate_rig(cfg, seed=2)
    g = run.truth(run.vo.t_s + cfg.camera_time_offset_s)
    Rc = g["R"] @ cfg.imu_T_camera[:3, :3]
    pc = g["p"] + np.einsum("nij,j->ni", g["R"], cfg.imu_T_camera[:3, 3])
    err = np.array([np.linalg.norm(run.vo.p[k] - Rc[k - 1].T @ (pc[k] - pc[k - 1])) for k in range(1, pc.shape[0])])
    out = run.vo_outliers[1:]
    assert 0.12 < out.mean() < 0.28 and run.vo.valid[1:].all()
    assert err[~out].max() < 1e-12 and err[out].min() >= 0.05 - 1e-12 and err[out].max() <= 0.2 + 1e-12
    ang = np.array([np.linalg.norm(so3_log((Rc[k - 1].T @ Rc[k]).T @ run.vo.R[k])) for k in range(1, pc.shape[0])])
    # the rotation error: 2-5 deg along a random normal direction (its length averages 1.60 / sqrt(3)): 3.2 deg
    assert ang[~out].max() < 1e-9 and 2.5 < np.degrees(ang[out]).mean() < 4.0


def test_keyframes_and_a_gap_in_tracking():
    cfg = RigConfig(duration_s=30.0, vo_keyframe_m=0.1, vo_keyframe_deg=5.0, vo_gap=(12.0, 2.0), stops=0, **EXACT)
    run = simulate_rig(cfg, seed=5)
    tau = run.vo.t_s + cfg.camera_time_offset_s
    lost = (tau >= 12.0) & (tau < 14.0)
    first_after = np.flatnonzero(tau >= 14.0)[0]
    np.testing.assert_array_equal(~run.vo.valid[1:], (lost | (np.arange(tau.size) == first_after))[1:])
    g = run.truth(tau)
    Rc = g["R"] @ cfg.imu_T_camera[:3, :3]
    pc = g["p"] + np.einsum("nij,j->ni", g["R"], cfg.imu_T_camera[:3, 3])
    key = 0
    for k in range(1, tau.size):
        assert run.vo.ref[k] == key, k
        Rt, pt = Rc[key].T @ Rc[k], Rc[key].T @ (pc[k] - pc[key])
        np.testing.assert_allclose(run.vo.p[k], pt, atol=1e-12)
        if lost[k] or np.linalg.norm(pt) > 0.1 or np.linalg.norm(so3_log(Rt)) > math.radians(5.0):
            key = k
    assert np.unique(run.vo.ref[1:]).size > 20


def test_a_cart_in_an_area_stays_in_it():
    cfg = RigConfig(duration_s=60.0, area=((1.0, 4.0), (-2.0, 0.5)), turn_rate_rad_s=1.0)
    run = simulate_rig(cfg, seed=1)
    p = run.truth(np.linspace(0, 60, 601))["p"]
    assert p[:, 0].min() > 1.0 - 0.5 and p[:, 0].max() < 4.0 + 0.5
    assert p[:, 1].min() > -2.0 - 0.5 and p[:, 1].max() < 0.5 + 0.5
    start = p[0, :2]
    assert abs(start[0] - 2.5) <= 0.3 + 1e-9 and abs(start[1] + 0.75) <= 0.3 + 1e-9
    with pytest.raises(InvalidDataError) as err:
        simulate_rig(RigConfig(duration_s=20.0, area=((0.0, 0.4), (0.0, 3.0))))
    assert str(err.value) == "area must be at least 0.5 m x 0.5 m, got ((0.0, 0.4), (0.0, 3.0))"


def test_seeds_fix_the_path_and_the_noise_apart():
    cfg = RigConfig(duration_s=10.0, still_start_s=1.0, still_end_s=1.0)
    a, b = simulate_rig(cfg, seed=1), simulate_rig(cfg, seed=1)
    np.testing.assert_array_equal(a.imu.accel, b.imu.accel)
    c = simulate_rig(cfg, seed=2, motion_seed=1)
    t = np.linspace(0, 10, 11)
    np.testing.assert_array_equal(c.truth(t)["p"], a.truth(t)["p"])
    assert not np.array_equal(c.imu.accel, a.imu.accel)
    d = simulate_rig(cfg, seed=1, motion_seed=2)
    assert not np.allclose(d.truth(t)["p"], a.truth(t)["p"])


# ------------------------------------------------------------------------------------------------ helpers

def test_the_default_mounts():
    Tbc = default_imu_T_camera()
    np.testing.assert_allclose(Tbc[:3, 3], [0.25, 0.0, 0.35], atol=0)
    c40, s40 = math.cos(math.radians(40)), math.sin(math.radians(40))
    np.testing.assert_allclose(Tbc[:3, 2], [c40, 0.0, -s40], atol=1e-12)  # looks forward, 40 deg down
    np.testing.assert_allclose(Tbc[:3, 0], [0.0, -1.0, 0.0], atol=1e-12)  # image x: to the cart's right
    np.testing.assert_allclose(Tbc[:3, 1], [-s40, 0.0, -c40], atol=1e-12)  # image y: down, tilted
    np.testing.assert_allclose(Tbc[3], [0, 0, 0, 1])
    np.testing.assert_allclose(default_imu_T_antenna(), [[1, 0, 0, -0.3], [0, 1, 0, 0], [0, 0, 1, -0.2], [0, 0, 0, 1]])


def test_antenna_truth_trajectory_and_wheel(exact_run):
    run = exact_run
    t = np.array([3.0, 7.5])
    g = run.truth(t)
    R, p = run.antenna_truth(t)
    np.testing.assert_allclose(R, g["R"], atol=1e-15)  # axes aligned
    np.testing.assert_allclose(p, g["p"] + np.einsum("nij,j->ni", g["R"], [-0.3, 0.0, -0.2]), atol=1e-15)
    traj = run.truth_trajectory(t)
    np.testing.assert_allclose(traj.positions_xyz, p, atol=1e-15)
    q = traj.orientations_quat_wxyz
    np.testing.assert_allclose(Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix(), R, atol=1e-12)
    assert run.truth_trajectory().timestamps_s.size == run.imu.t_s.size
    tw, d = run.wheel(scale_error=0.01, tick_m=0.002, rate_hz=50.0)
    np.testing.assert_allclose(tw, np.arange(0, 12.0 + 1e-9, 0.02), atol=1e-12)
    want = np.floor((run.truth.dist(tw) - run.truth.dist(0.0)) * 1.01 / 0.002) * 0.002
    np.testing.assert_allclose(d, want, atol=1e-12)
    assert d[-1] == pytest.approx(run.path_length_m * 1.01, abs=0.002) and np.all(np.diff(d) >= 0)


def test_the_filter_s_world_and_back(exact_run):
    run = exact_run
    t = np.array([0.0, 4.0, 9.0])
    Rf, pf = run.truth_in_filter_frame(t)
    np.testing.assert_allclose(pf[0], 0.0, atol=1e-12)
    assert math.atan2(Rf[0][1, 0], Rf[0][0, 0]) == pytest.approx(0.0, abs=1e-12)
    g = run.truth(t)
    # distances and tilts are the world's
    assert np.linalg.norm(pf[2] - pf[1]) == pytest.approx(np.linalg.norm(g["p"][2] - g["p"][1]), rel=1e-12)
    np.testing.assert_allclose(Rf[:, 2, :], g["R"][:, 2, :], atol=1e-12)
    back = run.to_world(Trajectory(t, pf, Rotation.from_matrix(Rf).as_quat()[:, [3, 0, 1, 2]]))
    np.testing.assert_allclose(back.positions_xyz, g["p"], atol=1e-12)
    Rb = Rotation.from_quat(back.orientations_quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()
    np.testing.assert_allclose(Rb, g["R"], atol=1e-12)


def test_loop_closures_are_the_true_relative_poses_with_their_noise():
    run = simulate_rig(RigConfig(duration_s=60.0, area=((0.0, 2.5), (0.0, 2.5)), turn_rate_rad_s=1.0), seed=3)
    frame_t = run.vo.t_s + run.config.camera_time_offset_s
    exact = run.loop_closures(frame_t, sigma_m=1e-12, sigma_deg=1e-12)
    assert len(exact) > 10
    g = run.truth(frame_t)
    for lc in exact:
        assert frame_t[lc.j] - frame_t[lc.i] >= 15.0
        np.testing.assert_allclose(lc.R, g["R"][lc.i].T @ g["R"][lc.j], atol=1e-9)
        np.testing.assert_allclose(lc.p, g["R"][lc.i].T @ (g["p"][lc.j] - g["p"][lc.i]), atol=1e-9)
    noisy = run.loop_closures(frame_t, sigma_m=0.01, sigma_deg=0.5)
    assert [(c.i, c.j) for c in noisy] == [(c.i, c.j) for c in exact]
    dp = np.array([c.p - e.p for c, e in zip(noisy, exact)])
    assert np.std(dp) == pytest.approx(0.01, rel=0.35)
    assert noisy[0].sigma_m == 0.01 and noisy[0].sigma_rad == pytest.approx(math.radians(0.5), rel=1e-15)
    wrong = run.loop_closures(frame_t, sigma_m=1e-12, sigma_deg=1e-12, outlier_rate=1.0)
    for c, e in zip(wrong, exact):
        off = c.p - e.p
        assert 0.2 - 1e-9 <= np.linalg.norm(off) <= 1.0 + 1e-9 and abs(off[2]) < 1e-9
        turn = math.degrees(np.linalg.norm(so3_log(e.R.T @ c.R)))
        assert 5 - 1e-6 <= turn <= 20 + 1e-6
    assert [(c.i, c.j) for c in run.loop_closures(frame_t, min_gap_s=1e6)] == []


def test_the_filter_config_matches_the_rig():
    cfg = RigConfig(duration_s=20.0, still_start_s=1.5, camera_time_offset_s=0.012)
    run = simulate_rig(cfg, seed=0)
    fc = run.filter_config(flat_ground_sigma_m=0.02)
    np.testing.assert_array_equal(fc.imu_T_camera, cfg.imu_T_camera)
    np.testing.assert_array_equal(fc.imu_T_antenna, cfg.imu_T_antenna)
    assert fc.camera_time_offset_s == 0.012 and fc.init_still_s == 1.5 and fc.flat_ground_sigma_m == 0.02
    assert simulate_rig(RigConfig(duration_s=20.0), seed=0).filter_config().init_still_s == 2.0
    assert run.filter_config(init_still_s=0.5).init_still_s == 0.5


@pytest.mark.parametrize("kw, msg", [
    ({"duration_s": 9.9}, "duration_s must leave at least 5 s of motion, got 9.9"),
    ({"duration_s": float("nan")}, "duration_s must leave at least 5 s of motion, got nan"),
    ({"imu_rate_hz": 0.0}, "imu_rate_hz must be positive, got 0.0"),
    ({"camera_rate_hz": -1.0}, "camera_rate_hz must be positive, got -1.0"),
    ({"camera_rate_hz": 300.0}, "camera_rate_hz must not exceed imu_rate_hz"),
    ({"vo_keyframe_m": 0.0}, "vo_keyframe_m must be positive or None, got 0.0"),
    ({"vo_keyframe_deg": 0.0}, "vo_keyframe_deg must be positive, got 0.0"),
])
def test_rig_config_names_each_wrong_value_in_full(kw, msg):
    with pytest.raises(InvalidDataError) as err:
        RigConfig(**kw)
    assert str(err.value) == msg


def test_rig_config_edges():
    RigConfig(duration_s=10.0)  # 3 + 2 + 5
    RigConfig(camera_rate_hz=200.0)
    c = RigConfig()
    assert (c.duration_s, c.imu_rate_hz, c.camera_rate_hz, c.speed_m_s, c.stops, c.still_start_s, c.still_end_s,
            c.camera_time_offset_s, c.vo_keyframe_m, c.vo_gap, c.area) == (90.0, 200.0, 15.0, (0.2, 0.6), 3, 3.0,
                                                                          2.0, 0.005, None, None, None)


def test_nees_runs_are_the_filter_s_nees_over_noise_draws_on_one_path():
    from gpr3d.pose.eskf import fuse
    from gpr3d.pose.metrics import nees

    cfg = RigConfig(duration_s=10.0, still_start_s=2.0, still_end_s=1.0, stops=0)
    got = nees_runs(cfg, 2, motion_seed=4, first_seed=30)
    want = []
    for s in (30, 31):
        run = simulate_rig(cfg, seed=s, motion_seed=4)
        res = fuse(run.imu, run.vo, run.filter_config())
        R_t, p_t = run.truth_in_filter_frame(res.frame_t_s)
        want.append(nees(res.frame_R, res.frame_p, res.frame_cov, R_t, p_t))
    np.testing.assert_array_equal(got, np.asarray(want))
    assert got.shape == (2, len(want[0])) and not np.array_equal(got[0], got[1])


# ------------------------------------------------------------------------------------------------ more edges

def test_rates_and_keyframe_angles_below_one_are_allowed():
    RigConfig(imu_rate_hz=0.9, camera_rate_hz=0.5)
    RigConfig(vo_keyframe_deg=0.5)


def test_the_random_motion_takes_both_signs_and_its_ranges():
    cfg = RigConfig(duration_s=60.0, turn_rate_rad_s=0.7)
    yaws, starts = [], []
    for seed in range(12):
        run = simulate_rig(cfg, seed=seed)
        knots = np.arange(0.0, 61.0)
        turn = run.truth.turn(knots)
        assert np.abs(turn).max() <= 0.7 + 1e-12
        if seed == 0:
            assert turn.min() < -0.1 and turn.max() > 0.1
        yaws.append(run.truth.yaw0)
        starts.append(run.truth(np.array([0.0]))["p"][0, :2])
    yaws, starts = np.array(yaws), np.array(starts)
    assert yaws.min() < -0.5 and yaws.max() > 0.5 and np.abs(yaws).max() <= np.pi
    assert starts.min() < -1 and starts.max() > 1 and np.abs(starts).max() <= 5
    assert not np.allclose(starts[:, 0], starts[:, 1])


def test_stops_are_still_spells_in_the_run():
    knots = np.arange(0.0, 61.0)
    for stops, seed in ((0, 1), (3, 1), (3, 2)):
        run = simulate_rig(RigConfig(duration_s=60.0, stops=stops), seed=seed)
        s = run.truth.speed(knots)
        inner = s[4:58]  # past the still start (3 s) and before the still end (2 s)
        still = np.flatnonzero(inner == 0.0)
        if stops == 0:
            assert still.size == 0
        else:
            assert 2 <= still.size <= 12  # 2-4 knots each, stops may overlap


def test_the_ground_waves_and_the_planned_turns():
    run = simulate_rig(RigConfig(duration_s=30.0), seed=2)
    for key, amp in (("roll", math.radians(1.5)), ("pitch", math.radians(1.5)), ("z", 0.01)):
        a, k, ph = run.truth.ground[key]
        assert a == pytest.approx(amp, rel=1e-12)
        assert 2 * np.pi / 3.0 <= k <= 2 * np.pi / 1.3 and 0 <= ph <= 2 * np.pi
    area = simulate_rig(RigConfig(duration_s=30.0, area=((0.0, 3.0), (0.0, 3.0))), seed=2)
    # steering plans the turn rate at whole seconds and holds it linear between (the plan is the path)
    t = np.array([5.5, 10.25, 17.75])
    lo, hi = area.truth.turn(np.floor(t)), area.truth.turn(np.ceil(t))
    np.testing.assert_allclose(area.truth.turn(t), lo + (t - np.floor(t)) * (hi - lo), rtol=0, atol=1e-12)


def test_a_single_time_gives_one_pose():
    run = simulate_rig(RigConfig(duration_s=10.0, still_start_s=1.0, still_end_s=1.0), seed=1)
    one, many = run.truth(5.0), run.truth(np.array([5.0]))
    for key in ("p", "v", "a", "w"):
        assert one[key].shape == (3,)
        np.testing.assert_array_equal(one[key], many[key][0])


@pytest.mark.parametrize("area, ok", [(((1.0, 1.3), (0.0, 3.0)), False), (((0.0, 0.5), (0.0, 3.0)), False),
                                      (((0.0, 3.0), (0.0, 0.5)), False), (((0.0, 1.0), (0.0, 1.0)), True),
                                      (((2.0, 2.6), (-1.0, -0.4)), True)])
def test_areas_must_be_wider_than_half_a_metre(area, ok):
    cfg = RigConfig(duration_s=12.0, area=area)
    if ok:
        run = simulate_rig(cfg, seed=0)
        (x0, x1), (y0, y1) = area
        start = run.truth(np.array([0.0]))["p"][0, :2]
        assert abs(start[0] - 0.5 * (x0 + x1)) <= 0.1 * (x1 - x0) + 1e-9
        assert abs(start[1] - 0.5 * (y0 + y1)) <= 0.1 * (x1 - x0) + 1e-9
    else:
        with pytest.raises(InvalidDataError) as err:
            simulate_rig(cfg, seed=0)
        assert str(err.value) == f"area must be at least 0.5 m x 0.5 m, got {area!r}"


def test_starts_in_an_area_spread_around_its_centre():
    off = []
    for seed in range(16):
        run = simulate_rig(RigConfig(duration_s=12.0, area=((1.0, 4.0), (-2.0, 0.5))), seed=seed)
        off.append(run.truth(np.array([0.0]))["p"][0, :2] - [2.5, -0.75])
    off = np.array(off)
    assert np.abs(off).max() <= 0.3 + 1e-9 and np.abs(off).max() > 0.15
    assert off.min() < 0 < off.max() and not np.allclose(off[:, 0], off[:, 1])


def test_wheel_defaults_and_a_start_without_a_still_spell():
    cfg = RigConfig(duration_s=10.0, still_start_s=0.0, still_end_s=1.0, stops=0, speed_m_s=(0.4, 0.5))
    run = simulate_rig(cfg, seed=3)
    t, d = run.wheel()
    np.testing.assert_allclose(t, np.arange(0, 10.0 + 1e-9, 0.01), atol=1e-12)
    want = np.floor((run.truth.dist(t) - run.truth.dist(0.0)) * 1.005 / 0.001) * 0.001
    np.testing.assert_allclose(d, want, atol=1e-12)
    assert d[0] == 0.0 and d[100] > 0.1
    # the filter's world starts at the first IMU sample, which moves already
    _, pf = run.truth_in_filter_frame(run.imu.t_s[[0, 1, 100]])
    np.testing.assert_allclose(pf[0], 0.0, atol=1e-12)
    assert np.linalg.norm(pf[1]) > 1e-9 and np.linalg.norm(pf[2]) > 1e-3
    g0 = run.truth(np.array([0.0]))
    back = run.to_world(Trajectory(np.array([0.0]), np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]])))
    np.testing.assert_allclose(back.positions_xyz[0], g0["p"][0], atol=1e-12)


def test_loop_closure_defaults_and_their_draws(monkeypatch):
    import gpr3d.pose.graph as graph

    run = simulate_rig(RigConfig(duration_s=60.0, area=((0.0, 2.5), (0.0, 2.5)), turn_rate_rad_s=1.0), seed=3)
    frame_t = run.vo.t_s + run.config.camera_time_offset_s
    a, b = run.loop_closures(frame_t), run.loop_closures(frame_t, seed=0)
    assert len(a) > 10 and all(np.array_equal(x.p, y.p) and np.array_equal(x.R, y.R) for x, y in zip(a, b))
    assert a[0].sigma_m == 0.003 and a[0].sigma_rad == pytest.approx(math.radians(0.1), rel=1e-15)
    other = run.loop_closures(frame_t, seed=1)
    assert not np.array_equal(other[0].p, a[0].p)
    # the noise is drawn per axis
    exact = run.loop_closures(frame_t, sigma_m=1e-12, sigma_deg=1e-12)
    dp = np.array([x.p - e.p for x, e in zip(a, exact)])
    assert not np.allclose(dp[:, 0], dp[:, 1])
    # wrong ones: of various sizes, turned either way
    wrong = run.loop_closures(frame_t, sigma_m=1e-12, sigma_deg=1e-12, outlier_rate=1.0)
    size = np.array([np.linalg.norm(w.p - e.p) for w, e in zip(wrong, exact)])
    turn = np.array([so3_log(e.R.T @ w.R)[2] for w, e in zip(wrong, exact)])
    assert size.std() > 0.1 and turn.min() < 0 < turn.max()
    seen = []
    real = graph.revisits
    monkeypatch.setattr(graph, "revisits", lambda *a_, **kw: seen.append(kw) or real(*a_, **kw))
    run.loop_closures(frame_t)
    run.loop_closures(frame_t, every_s=2.0, radius_m=0.3, max_angle_deg=30.0, min_gap_s=9.0)
    assert seen == [{"every_s": 1.0, "radius_m": 0.4, "max_angle_deg": 45.0, "min_gap_s": 15.0},
                    {"every_s": 2.0, "radius_m": 0.3, "max_angle_deg": 30.0, "min_gap_s": 9.0}]


def test_simulation_defaults_and_per_axis_draws():
    cfg = RigConfig(duration_s=10.0, still_start_s=1.0, still_end_s=1.0)
    a, b = simulate_rig(cfg), simulate_rig(cfg, seed=0)
    np.testing.assert_array_equal(a.imu.accel, b.imu.accel)
    np.testing.assert_array_equal(a.vo.p, b.vo.p)
    assert not np.allclose(a.accel_bias[0], a.accel_bias[0][0]) and not np.allclose(a.gyro_bias[0], a.gyro_bias[0][0])
    g = a.truth(a.vo.t_s + cfg.camera_time_offset_s)
    Rc = g["R"] @ cfg.imu_T_camera[:3, :3]
    pc = g["p"] + np.einsum("nij,j->ni", g["R"], cfg.imu_T_camera[:3, 3])
    err = np.array([a.vo.p[k] - Rc[k - 1].T @ (pc[k] - pc[k - 1]) for k in range(1, pc.shape[0])])
    assert not np.allclose(err[:, 0], err[:, 1])


def test_keyframes_without_a_gap_and_frame_0_is_never_an_outlier():
    run = simulate_rig(RigConfig(duration_s=20.0, vo_keyframe_m=0.1, vo_outlier_rate=1.0, stops=0), seed=4)
    assert not run.vo_outliers[0] and run.vo_outliers[1:].all()
    assert np.unique(run.vo.ref[1:]).size > 5


def test_nees_runs_defaults():
    cfg = RigConfig(duration_s=10.0, still_start_s=2.0, still_end_s=1.0, stops=0)
    np.testing.assert_array_equal(nees_runs(cfg, 1), nees_runs(cfg, 1, motion_seed=7, first_seed=100))
