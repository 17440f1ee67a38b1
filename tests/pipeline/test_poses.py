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
