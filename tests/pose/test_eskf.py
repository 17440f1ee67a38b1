"""The error-state EKF against the synthetic rig's exact truth."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.eskf import EskfConfig, _Filter, camera_to_imu_motion, fuse
from gpr3d.pose.imu import GRAVITY, ImuNoise, ImuSamples, so3_exp, so3_log
from gpr3d.pose.metrics import nees, nees_bounds
from gpr3d.pose.rig import RigConfig, nees_runs, simulate_rig

QUIET = ImuNoise(1e-12, 1e-12, 1e-12, 1e-12)


def _truth_in_filter_frame(run, t):
    return run.truth_in_filter_frame(t)


def test_noise_free_imu_integrates_to_the_truth():
    """The rig's analytic IMU (specific force, body rates from Euler rates) and the filter's propagation agree:
    dead reckoning over 20 s of turns, stops and uneven ground stays within a millimetre."""
    cfg = RigConfig(duration_s=20, accel_bias_sigma=1e-12, gyro_bias_sigma=1e-12, imu_noise=QUIET)
    run = simulate_rig(cfg, seed=1)
    g = run.truth(run.imu.t_s)
    f = _Filter(EskfConfig(), g["R"][0], np.zeros(3))
    f.p, f.v = g["p"][0].copy(), g["v"][0].copy()
    imu = run.imu
    for i in range(imu.t_s.size - 1):
        f.propagate(0.5 * (imu.accel[i] + imu.accel[i + 1]), 0.5 * (imu.gyro[i] + imu.gyro[i + 1]),
                    imu.t_s[i + 1] - imu.t_s[i])
    assert np.linalg.norm(f.p - g["p"][-1]) < 1e-3
    assert np.linalg.norm(so3_log(f.R.T @ g["R"][-1])) < 1e-5
    assert np.linalg.norm(g["p"][-1] - g["p"][0]) > 2.0  # it did travel


def test_camera_motion_maps_to_the_imu_motion_with_its_covariance():
    cfg = RigConfig(duration_s=20, vo_rot_deg=1e-12, vo_trans_frac=1e-12, vo_trans_floor_m=1e-12, vo_outlier_rate=0)
    run = simulate_rig(cfg, seed=2)
    tau = run.vo.t_s + cfg.camera_time_offset_s
    g = run.truth(tau)
    for k in (60, 150, 250):
        R_b, p_b, _ = camera_to_imu_motion(run.vo.R[k], run.vo.p[k], run.vo.cov[k], cfg.imu_T_camera)
        assert np.allclose(R_b, g["R"][k - 1].T @ g["R"][k], atol=1e-9)
        assert np.allclose(p_b, g["R"][k - 1].T @ (g["p"][k] - g["p"][k - 1]), atol=1e-9)
    # the covariance: noise drawn in the camera frame, mapped, against the returned covariance
    rng = np.random.default_rng(0)
    R_c, p_c = so3_exp([0.1, -0.2, 0.3]), np.array([0.05, -0.02, 0.3])
    cov_c = np.diag([1e-4, 2e-4, 3e-4, 1e-4, 4e-4, 2e-4])
    R_b, p_b, cov_b = camera_to_imu_motion(R_c, p_c, cov_c, cfg.imu_T_camera)
    errs = []
    for n in rng.multivariate_normal(np.zeros(6), cov_c, 20000):
        Rn, pn, _ = camera_to_imu_motion(R_c @ so3_exp(n[:3]), p_c + n[3:], cov_c, cfg.imu_T_camera)
        errs.append(np.concatenate([so3_log(R_b.T @ Rn), pn - p_b]))
    emp = np.cov(np.asarray(errs).T)
    assert np.allclose(emp, cov_b, atol=0.05 * np.abs(cov_b).max())


@pytest.fixture(scope="module")
def run60():
    cfg = RigConfig(duration_s=60)
    run = simulate_rig(cfg, seed=5)
    return cfg, run, fuse(run.imu, run.vo, run.filter_config())


def test_fusion_tracks_the_truth_and_rejects_odometry_outliers(run60):
    cfg, run, res = run60
    R_t, p_t = _truth_in_filter_frame(run, run.imu.t_s)
    err = np.linalg.norm(res.p - p_t, axis=1)
    assert run.path_length_m > 12
    assert np.sqrt(np.mean(err**2)) < 0.005 * run.path_length_m  # without any alignment
    # every gross odometry error is gated out, and almost no good frame is
    out = run.vo_outliers[np.searchsorted(run.vo.t_s + cfg.camera_time_offset_s, res.frame_t_s)]
    assert out.sum() >= 5 and np.all(res.vo_rejected[out])
    assert res.vo_rejected[~out].mean() < 0.01
    # the biases are learnt
    assert np.all(np.abs(res.gyro_bias[-1] - run.gyro_bias[-1]) < 3e-4)
    assert np.all(np.abs(res.accel_bias[-1] - run.accel_bias[-1]) < 0.03)


def test_fusion_is_better_than_odometry_alone():
    """Against the truth from the true start pose (no alignment): odometry alone drifts in tilt and heading, the
    fusion holds tilt to gravity and heading to the gyro. Better on every path, by a third or more overall."""
    fused, alone = [], []
    for seed in (6, 7, 8):
        cfg = RigConfig(duration_s=60, vo_outlier_rate=0.0)
        run = simulate_rig(cfg, seed=seed)
        res = fuse(run.imu, run.vo, run.filter_config())
        R_t, p_t = run.truth_in_filter_frame(run.vo.t_s + cfg.camera_time_offset_s)
        Rc, pc = run.vo.chained()  # camera poses in the first camera frame -> IMU poses in the filter's world
        Tbc = cfg.imu_T_camera
        Rb = Rc @ Tbc[:3, :3].T
        pb = pc - Rb @ Tbc[:3, 3]
        Rb0 = R_t[0] @ Rb[0].T  # odometry given the true start pose, as the filter's gravity alignment gives it
        p_vo = (Rb0 @ pb.T).T + (p_t[0] - Rb0 @ pb[0])
        alone.append(np.sqrt(np.mean(np.linalg.norm(p_vo - p_t, axis=1) ** 2)))
        fused.append(np.sqrt(np.mean(np.linalg.norm(res.frame_p - p_t, axis=1) ** 2)))
    assert all(f < a for f, a in zip(fused, alone)), (fused, alone)
    assert sum(fused) < 0.7 * sum(alone), (fused, alone)


def test_nees_stays_within_its_bounds():
    """Five noise draws on one path: the NEES of the pose, averaged over the runs, lies inside its two-sided
    95 % bounds at nearly 95 % of the frames, as a consistent filter's does."""
    runs = 5
    vals = nees_runs(RigConfig(duration_s=30), runs)
    avg = np.mean(vals, axis=0)[30:]  # after the first two seconds
    lo, hi = nees_bounds(runs)
    inside = np.mean((avg >= lo) & (avg <= hi))
    assert inside > 0.85, (inside, float(np.median(avg)))
    assert 0.5 * 6 < np.median(avg) < 1.5 * 6


def test_imu_bridges_a_gap_in_odometry():
    cfg = RigConfig(duration_s=40, vo_gap=(20.0, 2.0), vo_outlier_rate=0.0, stops=0)
    run = simulate_rig(cfg, seed=8)
    res = fuse(run.imu, run.vo, run.filter_config())
    R_t, p_t = _truth_in_filter_frame(run, run.imu.t_s)
    err = np.linalg.norm(res.p - p_t, axis=1)
    i0, i1 = np.searchsorted(run.imu.t_s, [20.0, 22.0])
    assert run.truth.dist(22.0) - run.truth.dist(20.0) > 0.3  # the cart moved in the gap
    assert err[i1] - err[i0] < 0.05
    assert not res.vo_used[(res.frame_t_s >= 20.0) & (res.frame_t_s < 22.0)].any()


def test_still_cart_gets_zero_velocity_updates(run60):
    cfg, run, res = run60
    still = run.truth(run.imu.t_s)["speed"] == 0.0
    assert res.zupt_count > 100
    assert np.median(np.linalg.norm(res.v[still], axis=1)) < 0.003


def test_antenna_trajectory_carries_the_lever_arm(run60):
    cfg, run, res = run60
    traj = res.antenna_trajectory()
    assert isinstance(traj, Trajectory) and len(traj) == run.imu.t_s.size
    R = Rotation.from_quat(traj.orientations_quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()
    back = traj.positions_xyz - np.einsum("nij,j->ni", res.R, cfg.imu_T_antenna[:3, 3])
    assert np.allclose(back, res.p, atol=1e-9) and np.allclose(R, res.R @ cfg.imu_T_antenna[:3, :3], atol=1e-9)


def test_bad_inputs_give_one_line():
    t = np.arange(0, 2, 0.005)
    acc = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    gyr = np.zeros((t.size, 3))
    with pytest.raises(InvalidDataError, match="in g"):
        ImuSamples(t, acc / 9.81, gyr)
    with pytest.raises(InvalidDataError, match="deg/s"):
        ImuSamples(t, acc, gyr + 57.0)
    with pytest.raises(InvalidDataError, match="must increase"):
        ImuSamples(t[::-1], acc, gyr)
    bad = acc.copy()
    bad[5, 1] = np.nan
    with pytest.raises(InvalidDataError, match="NaN"):
        ImuSamples(t, bad, gyr)
    moving = acc + np.random.default_rng(0).normal(0, 2.0, acc.shape)
    with pytest.raises(InvalidDataError, match="not still"):
        fuse(ImuSamples(t, moving, gyr), None, EskfConfig())
    with pytest.raises(InvalidDataError, match="not a rotation"):
        EskfConfig(imu_T_camera=np.diag([1.0, 1.0, 2.0, 1.0]))


def test_flat_ground_holds_the_height():
    """On a flat patch, a cart that stays on the ground: the height pseudo-measurement takes out the vertical
    drift that odometry's noise leaves, and the position error drops."""
    run = simulate_rig(RigConfig(duration_s=60, area=((0.0, 4.0), (0.0, 4.0)), turn_rate_rad_s=1.0), seed=4)
    _, p_t = run.truth_in_filter_frame(run.imu.t_s)
    free = fuse(run.imu, run.vo, run.filter_config())
    flat = fuse(run.imu, run.vo, run.filter_config(flat_ground_sigma_m=0.01))
    ez_free, ez_flat = (np.abs(r.p[:, 2] - p_t[:, 2]).mean() for r in (free, flat))
    assert ez_flat < 0.01 and ez_flat < 0.5 * ez_free
    e_free, e_flat = (np.linalg.norm(r.p - p_t, axis=1).mean() for r in (free, flat))
    assert e_flat < e_free
    with pytest.raises(InvalidDataError, match="flat_ground_sigma_m must be positive"):
        run.filter_config(flat_ground_sigma_m=0.0)


def test_survey_wheel_shortens_the_drift_across_an_odometry_gap():
    cfg = RigConfig(duration_s=40, vo_gap=(20.0, 5.0), vo_outlier_rate=0.0, stops=0)
    run = simulate_rig(cfg, seed=8)
    _, p_t = run.truth_in_filter_frame(run.imu.t_s)
    i0, i1 = np.searchsorted(run.imu.t_s, [20.0, 25.0])
    drift = []
    for wheel in (None, run.wheel()):
        res = fuse(run.imu, run.vo, run.filter_config(), wheel=wheel)
        e = np.linalg.norm(res.p - p_t, axis=1)
        drift.append(e[i1] - e[i0])
    assert drift[1] < 0.9 * drift[0], drift
    t, d = run.wheel()
    with pytest.raises(InvalidDataError, match="decreases"):
        fuse(run.imu, run.vo, run.filter_config(), wheel=(t, d[::-1]))


def test_fused_antenna_path_carried_to_the_site_frame_by_the_start_pose(run60):
    """``RigRun.to_world``: the fused antenna poses, put into the rig's world by the true start pose, follow the
    true antenna within the filter's drift without any alignment (the start differs only by the tilt estimate
    across the lever arm; a wrong heading or a lever arm left out would
    put them metres or decimetres off)."""
    cfg, run, res = run60
    est = run.to_world(res.antenna_trajectory())
    true = run.truth_trajectory()
    err = np.linalg.norm(est.positions_xyz - true.positions_xyz, axis=1)
    assert err[0] < 2e-3 and np.sqrt(np.mean(err**2)) < 0.005 * run.path_length_m
    Re = Rotation.from_quat(est.orientations_quat_wxyz[:, [1, 2, 3, 0]])
    Rt = Rotation.from_quat(true.orientations_quat_wxyz[:, [1, 2, 3, 0]])
    assert np.degrees(np.max((Re.inv() * Rt).magnitude())) < 1.5


def test_smoother_lowers_the_error_and_its_covariance_covers_it():
    """The RTS pass: on clean odometry (where the filter only equals odometry alone), the smoothed poses are
    closer to the truth than the filtered ones (APE at the IMU rate), its frame-to-frame jumps are gone
    (RPE), and its covariance is smaller than the filter's yet still covers the error (NEES near 6)."""
    from gpr3d.pose.metrics import ape, rpe

    cfg = RigConfig(duration_s=60, vo_outlier_rate=0.0)
    ratios, nees_s = [], []
    for seed in (3, 4):
        run = simulate_rig(cfg, seed=seed)
        f = fuse(run.imu, run.vo, run.filter_config())
        s = fuse(run.imu, run.vo, run.filter_config(), smooth=True)
        truth = run.truth_trajectory()
        ratios.append(ape(s.antenna_trajectory(), truth)["rmse"] / ape(f.antenna_trajectory(), truth)["rmse"])
        assert rpe(s.antenna_trajectory(), truth)["rmse"] < 0.5 * rpe(f.antenna_trajectory(), truth)["rmse"]
        R_t, p_t = run.truth_in_filter_frame(s.frame_t_s)
        assert np.median(np.trace(s.frame_cov[:, 3:, 3:], axis1=1, axis2=2)) < np.median(
            np.trace(f.frame_cov[:, 3:, 3:], axis1=1, axis2=2))
        nees_s.append(nees(s.frame_R, s.frame_p, s.frame_cov, R_t, p_t)[30:])
        # the velocities are corrected with the poses: the speed stays the cart's
        speed = np.linalg.norm(run.truth(run.imu.t_s)["v"], axis=1)
        assert np.abs(np.linalg.norm(s.v, axis=1) - speed).max() < 0.03
    assert max(ratios) < 0.9, ratios
    assert 3.0 < np.median(np.mean(nees_s, axis=0)) < 12.0


def test_keyframe_odometry_fuses_and_holds_a_standing_cart():
    """Odometry against keyframes (a new one every 10 cm or 5 deg, as pose.vo registers): the filter keeps its clone
    at the live keyframe, so each motion is applied from there. Over 60 s with stops, on the same path and noise
    as frame-to-frame odometry: the fused APE is a fraction of the frame-to-frame figure, the estimate moves less
    than half as much while the cart stands (from 0.5 s into each stop to its end), and zero-velocity updates never
    fire on a cart moving faster than 3 cm/s."""
    from gpr3d.pose.metrics import ape

    out, moved = {}, {}
    for kf in (None, 0.1):
        run = simulate_rig(RigConfig(duration_s=60, vo_keyframe_m=kf), seed=2)
        res = fuse(run.imu, run.vo, run.filter_config())
        traj = res.antenna_trajectory()
        out[kf] = ape(traj, run.truth_trajectory(traj.timestamps_s))["rmse"]
        still = run.truth(run.imu.t_s)["speed"] == 0.0
        d = np.diff(still.astype(int))
        starts, ends = np.flatnonzero(d == 1) + 1, np.flatnonzero(d == -1)
        stops = list(zip(starts, ends[ends > starts[0]]))  # the stops mid-run (not the still start)
        assert len(stops) >= 2 and all(b - a > 300 for a, b in stops)
        moved[kf] = np.mean([np.linalg.norm(res.p[b] - res.p[a + 100]) for a, b in stops])
        if kf:
            assert run.vo.keyframes and 100 < len(set(run.vo.ref.tolist())) < 0.5 * run.vo.t_s.size
            assert res.vo_used.sum() > 0.95 * run.vo.t_s.size
            assert run.truth(res.zupt_t_s)["speed"].max() < 0.03
            assert out[kf] < 0.005 * run.path_length_m
    assert out[0.1] < 0.6 * out[None], out
    assert moved[0.1] < min(0.01, 0.5 * moved[None]), moved


def test_the_filter_fed_as_the_data_come_gives_what_fuse_gives_and_its_poses_are_final_as_it_goes():
    """IMU, odometry (keyframes, a tracking gap, lagging the IMU by 0.3 s) and a wheel (lagging by 0.5 s: a frame
    waits for the wheel's distance up to it) fed in uneven chunks, the
    filter run between them: the poses it has passed never change afterwards, it keeps within the odometry's lag of
    the data, and at the end everything equals ``fuse`` (no smoothing) fed all at once, to the last bit."""
    from dataclasses import fields

    from gpr3d.pose.eskf import ForwardFusion

    run = simulate_rig(RigConfig(duration_s=16.0, vo_keyframe_m=0.1, vo_gap=(8.0, 1.0)), seed=3)
    assert run.vo.keyframes
    cfg = run.filter_config(flat_ground_sigma_m=0.01)
    wt, wd = run.wheel()
    ref = fuse(run.imu, run.vo, cfg, wheel=(wt, wd))
    imu, vo = run.imu, run.vo
    ff = ForwardFusion(cfg, rate_hz=imu.rate_hz, wheel=True)
    rng = np.random.default_rng(0)
    fed = {"imu": 0, "vo": 0, "wheel": 0}
    t, seen, lags = imu.t_s[0], 0, []
    while t < imu.t_s[-1] + 1.0:
        t += rng.uniform(0.01, 0.4)
        ni, nv, nw = (int(np.searchsorted(a, x, side="right")) for a, x in
                      ((imu.t_s, t), (vo.t_s + cfg.camera_time_offset_s, t - 0.3), (wt, t - 0.5)))
        ff.add_imu(imu.t_s[fed["imu"]:ni], imu.accel[fed["imu"]:ni], imu.gyro[fed["imu"]:ni])
        a = fed["vo"]
        ff.add_frames(vo.t_s[a:nv], vo.R[a:nv], vo.p[a:nv], vo.cov[a:nv], vo.valid[a:nv], vo.ref[a:nv])
        ff.add_wheel(wt[fed["wheel"]:nw], wd[fed["wheel"]:nw])
        fed.update(imu=ni, vo=nv, wheel=nw)
        moved = ff.run()
        n = ff.n_done
        assert moved == n - seen >= 0  # (how many more samples are final)
        np.testing.assert_array_equal(ff.out["p"][:n], ref.p[:n])  # final: what the whole run gives there
        if nv < vo.t_s.size and n:
            lags.append(t - imu.t_s[n - 1])
        seen = n
    # (the wheel's lag, a frame period, a chunk)
    assert seen > 0.9 * imu.t_s.size and max(lags) < 0.5 + 0.2 + 0.4
    got = ff.finish()
    for f in fields(got):
        np.testing.assert_array_equal(np.asarray(getattr(got, f.name)), np.asarray(getattr(ref, f.name)),
                                      err_msg=f.name)


def test_forward_fusion_names_wrong_input_in_one_line():
    from gpr3d.pose.eskf import ForwardFusion

    with pytest.raises(InvalidDataError, match="rate_hz must be a positive IMU sample rate, got 0"):
        ForwardFusion(rate_hz=0)
    with pytest.raises(InvalidDataError, match="got nan"):
        ForwardFusion(rate_hz=np.nan)
    with pytest.raises(InvalidDataError, match="got '200'"):
        ForwardFusion(rate_hz="200")
    in_g = ForwardFusion(EskfConfig(init_still_s=0.1), rate_hz=200.0)  # forces in g, not m/s^2: named at the start
    in_g.add_imu(np.arange(40) / 200.0, np.tile([0.0, 0.0, 1.0], (40, 1)), np.zeros((40, 3)))
    with pytest.raises(InvalidDataError, match=r"^IMU forces: median magnitude 1 is not in m/s\^2 \(in g\? "):
        in_g.run()
    ff = ForwardFusion(rate_hz=200.0)
    g = np.tile([0.0, 0.0, GRAVITY], (3, 1))
    ff.add_imu([0.0, 0.005, 0.01], g, np.zeros((3, 3)))
    for args, message in [
            (([0.01], g[:1], np.zeros((1, 3))), r"^IMU: timestamps must increase \(at 0.010000 s after 0.010000 s\)$"),
            (([0.02, 0.03], g[:1], np.zeros((2, 3))), r"^IMU forces: expected shape \(2, 3\), got \(1, 3\)$"),
            (([0.02], g[:1], np.zeros(3)), r"^IMU rates: expected shape \(1, 3\), got \(3,\)$"),
            (([0.02], [[0.0, np.nan, 9.81]], np.zeros((1, 3))), "^IMU samples from 3 on hold NaN/inf$"),
            (([0.02], g[:1], [[0.0, np.inf, 0.0]]), "^IMU samples from 3 on hold NaN/inf$"),
            (([np.nan], g[:1], np.zeros((1, 3))), "^IMU times hold NaN/inf$")]:
        with pytest.raises(InvalidDataError, match=message):
            ff.add_imu(*args)
    assert ff.imu_t.n == 3  # (nothing of a refused chunk kept)
    eye, c6 = np.tile(np.eye(3), (2, 1, 1)), np.tile(np.eye(6), (2, 1, 1))
    for kw, message in [
            (dict(ref=[-1, 1]), "^visual odometry ref: frame 1 refers to itself or a later frame$"),
            (dict(R=eye[:1]), r"^visual odometry R: expected shape \(2, 3, 3\), got \(1, 3, 3\)$"),
            (dict(p=np.zeros(3)), r"^visual odometry p: expected shape \(2, 3\), got \(3,\)$"),
            (dict(cov=c6[:, :3]), r"^visual odometry cov: expected shape \(2, 6, 6\), got \(2, 3, 6\)$"),
            (dict(valid=[True]), r"^visual odometry valid: expected shape \(2,\), got \(1,\)$"),
            (dict(ref=[-1, 0, 1]), r"^visual odometry ref: expected shape \(2,\), got \(3,\)$"),
            (dict(t_s=[0.1, 0.1]), r"^visual odometry: timestamps must increase \(at 0.100000 s after 0.100000 s\)$")]:
        args = {"t_s": [0.0, 0.1], "R": eye, "p": np.zeros((2, 3)), "cov": c6, **kw}
        with pytest.raises(InvalidDataError, match=message):
            ff.add_frames(**args)
    assert ff.vo_t.n == 0
    # frames in chunks: numbered on, each referring to the one before unless told; a non-finite motion, and
    # frame 0 (whose motion is from nothing), are failed frames
    bad = eye.copy()
    bad[1, 0, 0] = np.nan
    ff.add_frames([0.0, 0.1], eye, np.zeros((2, 3)), c6)
    ff.add_frames([0.2, 0.3], bad, np.zeros((2, 3)), c6, valid=[True, True], ref=[1, 1])
    assert ff.vo_ref[:].tolist() == [-1, 0, 1, 1] and ff.vo_valid[:].tolist() == [False, True, True, False]
    with pytest.raises(InvalidDataError, match=r"^wheel readings for a fusion made without a wheel \(wheel=True\)$"):
        ff.add_wheel([0.0], [0.0])
    fw = ForwardFusion(rate_hz=200.0, wheel=True)
    fw.add_wheel([0.0, 0.1], [0.0, 0.2])
    for args, message in [(([0.2], [0.1]), "^wheel: the distance decreases; pass the wheel's forward count$"),
                          (([0.2], [np.nan]), "^wheel distances hold NaN/inf$"),
                          (([0.2, 0.3], [0.3]), r"^wheel distances: expected shape \(2,\), got \(1,\)$"),
                          (([0.1], [0.3]), r"^wheel: timestamps must increase \(at 0.100000 s after 0.100000 s\)$")]:
        with pytest.raises(InvalidDataError, match=message):
            fw.add_wheel(*args)
    fw.add_wheel([0.2], [0.2])  # (standing still: the same distance again)
    assert fw.wheel[1][:].tolist() == [0.0, 0.2, 0.2]
    short = ForwardFusion(EskfConfig(init_still_s=2.0), rate_hz=200.0)
    short.add_imu(np.arange(100) / 200.0, np.tile([0.0, 0.0, GRAVITY], (100, 1)), np.zeros((100, 3)))
    assert short.run() == 0  # (the still start may go on)
    with pytest.raises(InvalidDataError, match=r"^the still start \(2 s: init_still_s, --still\) is longer than "
                                               r"the IMU record \(0.495 s\)$"):
        short.finish()
    with pytest.raises(InvalidDataError, match="^no IMU samples came$"):
        ForwardFusion(rate_hz=200.0).finish()
    with pytest.raises(InvalidDataError, match="^wheel: two readings at least$"):
        fuse(ImuSamples(np.arange(300) / 200.0, np.tile([0.0, 0.0, GRAVITY], (300, 1)), np.zeros((300, 3))),
             None, wheel=([0.0], [0.0]))


def test_forward_fusion_waits_for_the_still_start_then_runs_as_samples_come_and_gives_antenna_poses():
    from gpr3d.pose.eskf import ForwardFusion

    cfg = EskfConfig(init_still_s=0.1, imu_T_antenna=np.array([[1.0, 0, 0, 0.3], [0, 1, 0, 0], [0, 0, 1, -0.2],
                                                                 [0, 0, 0, 1]]))
    n = 100
    t, f, w = np.arange(n) / 200.0, np.tile([0.0, 0.0, GRAVITY], (n, 1)), np.zeros((n, 3))
    f[:, 0] += np.where(t > 0.2, 0.4, 0.0)  # (a push along x after the still start)
    ff = ForwardFusion(cfg, rate_hz=200.0)
    ff.end_frames()  # (no odometry will come)
    ff.add_imu(t[:21], f[:21], w[:21])  # up to 0.1 s: the still start's alignment may need more of it
    assert ff.run() == 0 and ff.n_done == 0 and ff.flt is None
    ff.add_imu(t[21:60], f[21:60], w[21:60])
    assert ff.run() == 60 and ff.run() == 0  # (everything that came, once)
    ff.add_imu(t[60:], f[60:], w[60:])
    assert ff.run() == n - 60
    res = ff.finish()
    ref = fuse(ImuSamples(t, f, w), None, cfg)
    np.testing.assert_array_equal(res.p, ref.p)
    assert res.p[-1, 0] > 1e-3  # (it moved)
    # the antenna's poses between the final samples: what the whole result's antenna trajectory gives there
    q = np.array([0.0, 0.0123, 0.25, 0.4949])
    want = ref.antenna_trajectory().at(q)
    got = ff.antenna_at(q)
    np.testing.assert_allclose(got.positions_xyz, want.positions_xyz, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.orientations_quat_wxyz, want.orientations_quat_wxyz, rtol=0, atol=1e-12)
    assert np.abs(got.positions_xyz[0] - [0.3, 0.0, -0.2]).max() < 1e-3  # (the mount: 0.3 m ahead, 0.2 m down)
    np.testing.assert_allclose(ff.antenna_at([0.4949]).positions_xyz, want.positions_xyz[-1:], rtol=0, atol=1e-12)
    last = ref.antenna_trajectory().at([0.495])  # (the last sample itself)
    np.testing.assert_allclose(ff.antenna_at([0.495]).positions_xyz, last.positions_xyz, rtol=0, atol=1e-12)
    with pytest.raises(InvalidDataError, match=r"^poses asked for outside the final ones \(their span: "
                                               r"0.000000..0.495000 s\)$"):
        ff.antenna_at([0.496])
    with pytest.raises(InvalidDataError, match=r"their span: none yet"):
        ForwardFusion(rate_hz=200.0).antenna_at([0.0])


def test_frames_wait_for_the_wheel_until_it_is_said_to_be_over():
    from gpr3d.pose.eskf import ForwardFusion

    run = simulate_rig(RigConfig(duration_s=12.0), seed=2)
    cfg = run.filter_config()
    wt, wd = run.wheel()
    imu, vo = run.imu, run.vo
    ff = ForwardFusion(cfg, rate_hz=imu.rate_hz, wheel=True)
    ff.add_imu(imu.t_s, imu.accel, imu.gyro)
    ff.add_frames(vo.t_s, vo.R, vo.p, vo.cov, vo.valid, vo.ref)
    ff.end_frames()
    stop = int(np.searchsorted(wt, 8.0))
    ff.add_wheel(wt[:stop], wd[:stop])  # the wheel stops reporting at 8 s
    ff.run()
    held = ff.n_done
    assert 8.0 - 1 / 15 < imu.t_s[held - 1] < 8.0 + 1 / 15 and held < imu.t_s.size  # (later frames wait for it)
    ff.end_wheel()
    ff.run()
    assert ff.n_done == imu.t_s.size  # (no stall: the last reading holds)
    ref = fuse(imu, vo, cfg, wheel=(wt[:stop], wd[:stop]))
    np.testing.assert_array_equal(ff.out["p"][:], ref.p)
