"""Open3D RGB-D odometry on rendered frames: motions against the truth, failures reported, inputs checked."""

import dataclasses

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.imu import so3_log
from gpr3d.pose.render import CameraIntrinsics, FloorScene, render_rgbd, rig_camera_poses
from gpr3d.pose.rig import RigConfig, simulate_rig

pytest.importorskip("open3d", exc_type=ImportError)
from gpr3d.pose.vo import OdometryConfig, rgbd_odometry  # noqa: E402

INTR = CameraIntrinsics.d435i(320)


@pytest.fixture(scope="module")
def cart():
    run = simulate_rig(RigConfig(duration_s=10, still_start_s=1.0, still_end_s=1.0), seed=4)
    sel = (run.vo.t_s > 1.5) & (run.vo.t_s < 3.5)  # 2 s of motion: 30 frames
    t = run.vo.t_s[sel]
    return run, t, rig_camera_poses(run, t + run.config.camera_time_offset_s)


def _frames(scene, t, T, seed=0):
    rng = np.random.default_rng(seed)
    for k in range(t.size):
        c, d = render_rgbd(scene, INTR, T[k], rng=rng)
        yield t[k], c, d


def test_odometry_follows_the_true_camera_motion(cart):
    run, t, T = cart
    vo, rep = rgbd_odometry(_frames(FloorScene.random(seed=4), t, T), INTR)
    assert rep["registered"] == t.size - 1 and not rep["lost"]
    assert 3 <= rep["keyframes"] < t.size // 2 and vo.keyframes  # 10 cm apart over ~0.8 m
    err, nees, step = [], [], []
    for k in range(1, t.size):
        Tt = np.linalg.inv(T[vo.ref[k]]) @ T[k]  # camera k in its keyframe
        e = np.concatenate([so3_log(vo.R[k].T @ Tt[:3, :3]), Tt[:3, 3] - vo.p[k]])
        err.append(e)
        nees.append(e @ np.linalg.solve(vo.cov[k], e))
        step.append(np.linalg.norm(Tt[:3, 3]))
    err = np.array(err)
    assert np.mean(step) > 0.03  # it moved (a swapped or uninverted motion would be off by twice that)
    assert np.sqrt(np.mean(np.sum(err[:, 3:] ** 2, 1))) < 0.003
    assert np.degrees(np.sqrt(np.mean(np.sum(err[:, :3] ** 2, 1)))) < 0.3
    assert 0.1 < np.median(nees) < 20.0  # the calibrated covariance has the right size (NEES median 2.3 on 1800 frames)
    # chained, the motions reproduce the path over 2 s within a centimetre
    measured = dataclasses.replace(run, vo=vo)
    Rc, pc = measured.vo.chained()
    true = np.array([(np.linalg.inv(T[0]) @ T[k])[:3, 3] for k in range(t.size)])
    assert np.max(np.linalg.norm(pc - true, axis=1)) < 0.01


def test_keyframes_keep_a_standing_camera_from_drifting(cart):
    """A camera standing still for 40 frames (sensor noise only): registered to one keyframe, its chained pose stays
    within one registration's error (~1 mm) of the start; frame to frame, the per-frame errors add up (a random
    walk: several times that by the last frames)."""
    run, t, T = cart
    still = np.repeat(T[:1], 40, axis=0)
    tt = np.arange(40) / 15.0
    drift = {}
    for kf in (0.1, 0.0):
        vo, rep = rgbd_odometry(_frames(FloorScene.random(seed=4), tt, still, seed=3), INTR,
                                OdometryConfig(keyframe_m=kf))
        assert rep["registered"] == 39
        _, pc = vo.chained()
        d = np.linalg.norm(pc, axis=1)
        drift[kf] = d[-10:].mean()
        assert rep["keyframes"] == (1 if kf else 40)
        if kf:
            assert d.max() < 3e-3
    assert drift[0.1] < 1.5e-3
    assert drift[0.0] > 2 * drift[0.1]


def test_plain_floor_is_reported_lost_not_used(cart):
    run, t, T = cart
    vo, rep = rgbd_odometry(_frames(FloorScene(texture=False), t[:10], T[:10]), INTR)
    assert rep["registered"] == 0 and rep["lost"] == {"too little texture": 9}
    assert not vo.valid.any()


def test_bad_frames_give_one_line(cart):
    run, t, T = cart
    c, d = render_rgbd(FloorScene(), INTR, T[0])
    with pytest.raises(InvalidDataError, match="do not match"):
        rgbd_odometry([(0.0, c, d), (0.1, c[:-1], d[:-1])], INTR)
    with pytest.raises(InvalidDataError, match="does not increase"):
        rgbd_odometry([(0.0, c, d), (0.0, c, d)], INTR)
    with pytest.raises(InvalidDataError, match="min_texture"):
        OdometryConfig(min_texture=1.5)


def test_loop_closures_from_rendered_revisits_take_out_the_drift():
    """A cart crossing its own path over 120 s: revisits found from the fused poses, registered by Open3D, agree
    with the true relative poses within a few mm, and closing the loops cuts the APE by half or more."""
    from gpr3d.pose.eskf import fuse
    from gpr3d.pose.graph import GraphConfig, close_loops
    from gpr3d.pose.metrics import ape
    from gpr3d.pose.vo import rgbd_loop_closures

    rig = RigConfig(duration_s=120, area=((0.0, 3.0), (0.0, 3.0)), turn_rate_rad_s=1.0, stops=2,
                    vo_trans_frac=0.03, vo_trans_floor_m=1e-3)
    run = simulate_rig(rig, seed=5)
    res = fuse(run.imu, run.vo, run.filter_config(flat_ground_sigma_m=0.01), smooth=True)
    scene = FloorScene.random(area=((-3.0, 6.0), (-3.0, 6.0)), n_boxes=30, seed=5)
    T = rig_camera_poses(run, res.frame_t_s)
    intr = CameraIntrinsics.d435i(320)
    closures, rep = rgbd_loop_closures(lambda k: render_rgbd(scene, intr, T[k], rng=np.random.default_rng(k)), res,
                                       intr, rig.imu_T_camera)
    assert len(closures) >= 10 and rep["closures"] == len(closures)
    g = run.truth(res.frame_t_s)
    err = [np.linalg.norm(c.p - g["R"][c.i].T @ (g["p"][c.j] - g["p"][c.i])) for c in closures]
    assert np.median(err) < 0.003
    truth = run.truth_trajectory()
    before = ape(res.antenna_trajectory(), truth)["rmse"]
    after = ape(close_loops(res, closures, GraphConfig(trans_frac=0.03, trans_floor_m=1e-3)).antenna_trajectory(),
                truth)["rmse"]
    assert after < 0.5 * before, (before, after)
