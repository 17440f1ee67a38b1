"""IMU / wheel CSV, rig JSON and odometry poses -> frame-to-frame motions."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import FormatError
from gpr3d.core.trajectory import Trajectory
from gpr3d.io.inertial import (read_imu_csv, read_rig, read_wheel_csv, relative_from_camera_poses, write_imu_csv,
                               write_rig, write_wheel_csv)
from gpr3d.pose.rig import RigConfig, simulate_rig


def test_round_trips(tmp_path):
    run = simulate_rig(RigConfig(duration_s=20), seed=1)
    write_imu_csv(run.imu, tmp_path / "imu.csv")
    back = read_imu_csv(tmp_path / "imu.csv")
    assert np.allclose(back.t_s, run.imu.t_s, atol=1e-6) and np.allclose(back.accel, run.imu.accel, rtol=1e-6)
    assert np.allclose(back.gyro, run.imu.gyro, rtol=1e-6, atol=1e-12)
    t, d = run.wheel()
    write_wheel_csv(t, d, tmp_path / "w.csv")
    t2, d2 = read_wheel_csv(tmp_path / "w.csv")
    assert np.allclose(t2, t) and np.allclose(d2, d, atol=1e-4)
    cfg = run.config
    write_rig(tmp_path / "rig.json", imu_T_camera=cfg.imu_T_camera, imu_T_antenna=cfg.imu_T_antenna,
              camera_time_offset_s=0.005)
    rig = read_rig(tmp_path / "rig.json")
    assert np.allclose(rig["imu_T_camera"], cfg.imu_T_camera) and rig["camera_time_offset_s"] == 0.005


def test_bad_files_name_the_problem(tmp_path):
    (tmp_path / "g.csv").write_text("t,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.01},0,0,1,0,0,0\n" for i in range(50)))
    with pytest.raises(FormatError, match="in g"):
        read_imu_csv(tmp_path / "g.csv")
    (tmp_path / "n.csv").write_text("t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.01,0,0,nan,0,0,0\n")
    with pytest.raises(FormatError, match="NaN"):
        read_imu_csv(tmp_path / "n.csv")
    (tmp_path / "r.json").write_text('{"imu_T_camera": [[1, 0], [0, 1]]}')
    with pytest.raises(FormatError, match="4 x 4"):
        read_rig(tmp_path / "r.json")


def test_camera_poses_give_the_rig_s_motions_and_a_gap_where_frames_are_missing():
    run = simulate_rig(RigConfig(duration_s=20, vo_outlier_rate=0.0), seed=2)
    Rc, pc = run.vo.chained()
    keep = np.ones(len(pc), bool)
    keep[100:130] = False  # two seconds of lost tracking
    traj = Trajectory(run.vo.t_s[keep], pc[keep], Rotation.from_matrix(Rc[keep]).as_quat()[:, [3, 0, 1, 2]])
    rel = relative_from_camera_poses(traj)
    idx = np.nonzero(keep)[0]
    gap = int(np.searchsorted(idx, 130))
    assert not rel.valid[gap] and rel.valid[1:gap].all() and rel.valid[gap + 1 :].all()
    for j in (5, gap - 1, gap + 3):
        k = idx[j]
        assert np.allclose(rel.R[j], run.vo.R[k], atol=1e-9) and np.allclose(rel.p[j], run.vo.p[k], atol=1e-9)
    assert rel.cov[5, 0, 0] == pytest.approx(np.deg2rad(0.03) ** 2)
