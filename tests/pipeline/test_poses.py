"""gpr3d.pipeline.fuse_recordings: files in, the filter run with the settings given (the same poses as the filter
called by hand on the same recordings), the antenna's path out."""

import numpy as np
import pytest

from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import fuse_recordings


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    from gpr3d.io.inertial import write_imu_csv, write_rig, write_wheel_csv
    from gpr3d.pose.rig import RigConfig, simulate_rig

    d = tmp_path_factory.mktemp("rig")
    run = simulate_rig(RigConfig(duration_s=25), seed=3)
    write_imu_csv(run.imu, d / "imu.csv")
    write_wheel_csv(*run.wheel(), d / "wheel.csv")
    cfg = run.config
    write_rig(d / "rig.json", imu_T_camera=cfg.imu_T_camera, imu_T_antenna=cfg.imu_T_antenna,
              camera_time_offset_s=cfg.camera_time_offset_s)
    from scipy.spatial.transform import Rotation

    from gpr3d.core.trajectory import Trajectory
    from gpr3d.io.trajectory import write_tum

    keep = run.vo.valid.copy()
    keep[0] = True
    Rc, pc = run.vo.chained()
    write_tum(Trajectory(run.vo.t_s[keep], pc[keep], Rotation.from_matrix(Rc[keep]).as_quat()[:, [3, 0, 1, 2]]),
              d / "odometry.tum")
    return d, run


def test_the_poses_are_the_filters_on_the_same_recordings(rig):
    from gpr3d.io.inertial import read_imu_csv, read_rig, read_wheel_csv, relative_from_camera_poses
    from gpr3d.io.trajectory import read_trajectory
    from gpr3d.pose.eskf import EskfConfig, fuse
    from gpr3d.pose.metrics import ape

    d, run = rig
    got = fuse_recordings(imu=d / "imu.csv", odometry=d / "odometry.tum", wheel=d / "wheel.csv", rig=d / "rig.json",
                          odometry_sigma=(0.05, 0.02, 0.001), still_s=2.0, log=lambda *_: None)
    vo = relative_from_camera_poses(read_trajectory(d / "odometry.tum"), rot_sigma_deg=0.05, trans_frac=0.02,
                                    trans_floor_m=0.001)
    ref = fuse(read_imu_csv(d / "imu.csv"), vo, EskfConfig(init_still_s=2.0, **read_rig(d / "rig.json")),
               wheel=read_wheel_csv(d / "wheel.csv"))
    np.testing.assert_array_equal(got.trajectory.positions_xyz, ref.antenna_trajectory().positions_xyz)
    assert got.source == str(d / "imu.csv")
    assert ape(got.trajectory, run.truth_trajectory())["rmse"] < 0.05  # and it is the cart's path


def test_an_offset_asked_for_without_odometry_is_one_line(rig):
    d, _ = rig
    with pytest.raises(GPR3DError, match="--estimate-offset needs odometry"):
        fuse_recordings(imu=d / "imu.csv", estimate_offset=True)


def test_the_rig_s_recordings_read_back_as_written_and_poses_reach_the_traces_by_time(tmp_path):
    from scipy.spatial.transform import Rotation

    from gpr3d import Survey
    from gpr3d.core.trajectory import Trajectory
    from gpr3d.io.inertial import read_imu_csv, read_rig, read_wheel_csv
    from gpr3d.io.trajectory import read_trajectory
    from gpr3d.pipeline import poses_at_traces, write_rig_recordings
    from gpr3d.pose.rig import RigConfig, simulate_rig

    run = simulate_rig(RigConfig(duration_s=20, vo_gap=(10.0, 2.0)), seed=1)
    names = write_rig_recordings(run, tmp_path / "r")
    assert sorted(names) == sorted(p.name for p in (tmp_path / "r").iterdir())
    imu = read_imu_csv(tmp_path / "r" / "imu.csv")
    np.testing.assert_allclose(imu.t_s, run.imu.t_s)
    np.testing.assert_allclose(imu.gyro, run.imu.gyro, rtol=1e-6)
    t, d = read_wheel_csv(tmp_path / "r" / "wheel.csv")
    np.testing.assert_allclose(d, run.wheel()[1])
    assert np.allclose(read_rig(tmp_path / "r" / "rig.json")["imu_T_antenna"], run.config.imu_T_antenna)
    cam = read_trajectory(tmp_path / "r" / "odometry.tum")
    # the camera's chained poses, the frames lost in the gap left out
    Rc, pc = run.vo.chained()
    keep = run.vo.valid.copy()
    keep[0] = True
    assert len(cam) == keep.sum() < len(run.vo.t_s)
    np.testing.assert_allclose(cam.positions_xyz, pc[keep], atol=1e-12)
    np.testing.assert_allclose(np.abs(np.sum(cam.orientations_quat_wxyz
                                             * Rotation.from_matrix(Rc[keep]).as_quat()[:, [3, 0, 1, 2]], axis=1)), 1.0)

    # a straight, steady path: at any trace time the pose is the line's point there
    tt = np.linspace(0.0, 10.0, 11)
    traj = Trajectory(tt, np.c_[0.5 * tt, 2.0 + 0 * tt, 0 * tt], np.tile([1.0, 0, 0, 0], (11, 1)))
    s = Survey(data=np.zeros((4, 8), np.float32), dt_s=1e-10, timestamps_s=[0.25, 3.5, 7.0, 9.9])
    got = poses_at_traces(traj, s)
    np.testing.assert_allclose(got.positions_xyz[:, 0], [0.125, 1.75, 3.5, 4.95])
    np.testing.assert_allclose(got.timestamps_s, s.timestamps_s)
    with pytest.raises(GPR3DError, match="line.h5: its traces have no times"):
        poses_at_traces(traj, s.replace(timestamps_s=None), source="line.h5")
    with pytest.raises(GPR3DError, match="^late.h5: "):
        poses_at_traces(traj, s.replace(timestamps_s=[1.0, 2.0, 3.0, 12.0]), source="late.h5")
