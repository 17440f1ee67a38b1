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
    assert rel.cov[5, 0, 0] == pytest.approx(np.deg2rad(0.03) ** 2, rel=1e-9, abs=0)


def test_euroc_imu_and_ground_truth_files(tmp_path):
    """EuRoC MAV's column layout (gyro before accelerometer, nanosecond stamps, units in brackets) reads into the
    same values as our own CSV."""
    from gpr3d.io.trajectory import read_trajectory

    run = simulate_rig(RigConfig(duration_s=10, still_start_s=1, still_end_s=1), seed=2)
    imu = run.imu
    t_ns = (1403636579758555392 + np.round(imu.t_s * 1e9)).astype(np.int64)
    lines = ["#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
             "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"]
    lines += [f"{t}," + ",".join(repr(float(v)) for v in (*g, *a)) for t, g, a in zip(t_ns, imu.gyro, imu.accel)]
    (tmp_path / "data.csv").write_text("\n".join(lines) + "\n")
    back = read_imu_csv(tmp_path / "data.csv")
    np.testing.assert_array_equal(back.accel, imu.accel)
    np.testing.assert_array_equal(back.gyro, imu.gyro)
    np.testing.assert_allclose(back.t_s - back.t_s[0], imu.t_s - imu.t_s[0], atol=1e-6)
    assert back.t_s[0] == pytest.approx(1403636579.758555392, abs=1e-6)
    tr = run.truth_trajectory(imu.t_s[::20])
    rows = ["#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
            "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1]"]
    rows += [f"{t}," + ",".join(repr(float(v)) for v in (*p, *q, 0.0, 0.0, 0.0))
             for t, p, q in zip(t_ns[::20], tr.positions_xyz, tr.orientations_quat_wxyz)]
    (tmp_path / "gt.csv").write_text("\n".join(rows) + "\n")
    gt = read_trajectory(tmp_path / "gt.csv")
    np.testing.assert_array_equal(gt.positions_xyz, tr.positions_xyz)
    np.testing.assert_allclose(np.abs(np.sum(gt.orientations_quat_wxyz * tr.orientations_quat_wxyz, 1)), 1.0)
    np.testing.assert_allclose(np.diff(gt.timestamps_s), np.diff(tr.timestamps_s), atol=1e-6)
