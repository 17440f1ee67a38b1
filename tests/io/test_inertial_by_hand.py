"""The inertial readers' every message in full, EuRoC's headers, the files as written, and the odometry motions'
covariances and gaps by hand."""

import json
import math

import numpy as np
import pytest

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.io.inertial import (csv_header, read_imu_csv, read_rig, read_wheel_csv, relative_from_camera_poses,
                               write_rig, write_wheel_csv)


def test_csv_headers_ours_and_euroc_s():
    assert csv_header([" T ", "AX", "distance"]) == (["t", "ax", "distance"], 1.0)
    names, scale = csv_header(["#timestamp [ns]", "w_RS_S_x [rad s^-1]", "a_RS_S_z [m s^-2]", "p_RS_R_x [m]"])
    assert (names, scale) == (["t", "gx", "az", "x"], 1e-9)
    # a plain 'timestamp' is EuRoC's only with its [ns]; EuRoC names without their _RS_ marks stay as they are
    assert csv_header(["timestamp [ns]", "q_RS_w []"]) == (["t", "qw"], 1e-9)
    assert csv_header(["timestamp", "gx"]) == (["timestamp", "gx"], 1.0)
    assert csv_header(["timestamp [s]", "w_RS_S_x"]) == (["timestamp [s]", "gx"], 1.0)


def _csv(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text, message", [
    ("", "d.csv: file is empty"),
    ("\n", "d.csv: IMU CSV header lacks column(s) ['t', 'ax', 'ay', 'az', 'gx', 'gy', 'gz'] (has [])"),
    ("t,ax,ay,az,gx,gy\n", "d.csv: IMU CSV header lacks column(s) ['gz'] (has ['t', 'ax', 'ay', 'az', 'gx', 'gy'])"),
    ("t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n\n , ,\n0.01,0,0,9.8,0,0,x\n", "d.csv: line 5: bad or missing number"),
    ("t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0\n", "d.csv: line 3: bad or missing number"),
    ("t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n", "d.csv: holds 1 IMU sample(s); two at least are needed"),
    ("t,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n0.01,0,0,nan,0,0,0\n", "d.csv: holds NaN/inf values"),
])
def test_imu_csv_messages_in_full(tmp_path, text, message):
    with pytest.raises(FormatError) as err:
        read_imu_csv(_csv(tmp_path, text))
    assert str(err.value) == message


def test_an_empty_first_line_and_the_samples_checks_name_the_file(tmp_path):
    p = _csv(tmp_path, "t,ax,ay,az,gx,gy,gz\n0.02,0,0,9.8,0,0,0\n0.01,0,0,9.8,0,0,0\n")  # time going back
    with pytest.raises(FormatError) as err:
        read_imu_csv(p)
    assert str(err.value).startswith("d.csv: ") and err.value.path == str(p)


def test_imu_and_wheel_columns_in_any_order_and_euroc_nanoseconds(tmp_path):
    p = _csv(tmp_path, "gz,gy,gx,az,ay,ax,t,extra\n6,5,4,3,2,1,0.5,9\n\n16,15,14,13,12,11,0.6,9\n")
    imu = read_imu_csv(p)
    np.testing.assert_array_equal(imu.t_s, [0.5, 0.6])
    np.testing.assert_array_equal(imu.accel, [[1, 2, 3], [11, 12, 13]])
    np.testing.assert_array_equal(imu.gyro, [[4, 5, 6], [14, 15, 16]])
    e = _csv(tmp_path, "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                       "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
                       "1403636579758555392,0.1,0.2,0.3,1,2,9\n1403636579763555584,0.1,0.2,0.3,1,2,9\n", "e.csv")
    imu = read_imu_csv(e)
    assert imu.t_s[0] == pytest.approx(1403636579.758555392, abs=1e-6)
    assert imu.t_s[1] - imu.t_s[0] == pytest.approx(0.005, abs=1e-6)
    np.testing.assert_array_equal(imu.gyro[0], [0.1, 0.2, 0.3])
    w = _csv(tmp_path, "distance,t\n0.0,1.0\n0.25,1.5\n", "w.csv")
    t, d = read_wheel_csv(w)
    assert t.tolist() == [1.0, 1.5] and d.tolist() == [0.0, 0.25]
    with pytest.raises(FormatError) as err:
        read_wheel_csv(_csv(tmp_path, "t,dist\n0,0\n1,1\n", "x.csv"))
    assert str(err.value) == "x.csv: wheel CSV header lacks column(s) ['distance'] (has ['t', 'dist'])"


def test_files_as_written(tmp_path):
    write_wheel_csv([0.0, 0.1234567], [0.0, 1.23456], tmp_path / "w.csv")
    assert (tmp_path / "w.csv").read_text() == "t,distance\n0.000000,0.0000\n0.123457,1.2346\n"
    T = np.eye(4)
    T[0, 3] = 0.25
    write_rig(tmp_path / "r.json", imu_T_camera=T, imu_T_antenna=np.eye(4), camera_time_offset_s=0.02)
    text = (tmp_path / "r.json").read_text()
    assert text == json.dumps({"imu_T_camera": T.tolist(), "imu_T_antenna": np.eye(4).tolist(),
                               "camera_time_offset_s": 0.02}, indent=1)
    rig = read_rig(tmp_path / "r.json")
    assert set(rig) == {"imu_T_camera", "imu_T_antenna", "camera_time_offset_s"}
    assert rig["imu_T_camera"].dtype == np.float64 and rig["imu_T_camera"][0, 3] == 0.25


@pytest.mark.parametrize("content, message", [
    ("{", "r.json: not JSON (Expecting property name enclosed in double quotes, line 1)"),
    ('{"imu_T_antenna": [[1, 0], [0, 1]]}', "r.json: imu_T_antenna must be a 4 x 4 matrix, got shape (2, 2)"),
    ('{"imu_T_camera": [1, 2, 3]}', "r.json: imu_T_camera must be a 4 x 4 matrix, got shape (3,)"),
    ('{"camera_time_offset_s": 0.1, "zz": 1, "aa": 2}', "r.json: unknown rig key(s) ['aa', 'zz']"),
])
def test_rig_messages_in_full(tmp_path, content, message):
    (tmp_path / "r.json").write_text(content)
    with pytest.raises(FormatError) as err:
        read_rig(tmp_path / "r.json")
    assert str(err.value) == message


def test_a_rig_of_integers_reads_as_floats(tmp_path):
    (tmp_path / "r.json").write_text(json.dumps({"imu_T_antenna": np.eye(4, dtype=int).tolist()}))
    rig = read_rig(tmp_path / "r.json")
    assert rig["imu_T_antenna"].dtype == np.float64 and set(rig) == {"imu_T_antenna"}


def test_camera_motions_covariances_and_gaps_by_hand():
    from scipy.spatial.transform import Rotation

    from gpr3d.core.trajectory import Trajectory

    t = np.array([0.0, 0.1, 0.2, 0.3, 0.45, 0.6])  # 0.15 s steps: exactly 1.5 x the median 0.1: kept
    t[5] = 0.76  # 0.31 s: a gap
    yaw = np.deg2rad([0, 10, 20, 30, 40, 50])
    R = Rotation.from_euler("z", yaw[:, None])
    p = np.stack([np.arange(6) * 0.2, np.zeros(6), np.zeros(6)], 1)
    q = R.as_quat()[:, [3, 0, 1, 2]]
    rel = relative_from_camera_poses(Trajectory(t, p, q))
    assert rel.valid.tolist() == [False, True, True, True, True, False]
    Rm = R.as_matrix()
    for k in range(1, 6):
        np.testing.assert_allclose(rel.R[k], Rm[k - 1].T @ Rm[k], rtol=0, atol=1e-12)
        want = Rm[k - 1].T @ (p[k] - p[k - 1])  # in the earlier camera's frame: 0.2 m at -10 deg, -20 deg...
        np.testing.assert_allclose(rel.p[k], want, rtol=0, atol=1e-12)
        st = 0.01 * 0.2 + 5e-4
        np.testing.assert_allclose(rel.cov[k], np.diag([np.deg2rad(0.03) ** 2] * 3 + [st**2] * 3), rtol=1e-12,
                                   atol=0)
    np.testing.assert_allclose(rel.cov[0], np.diag([np.deg2rad(0.03) ** 2] * 3 + [(5e-4) ** 2] * 3), rtol=1e-12,
                               atol=0)
    assert np.array_equal(rel.R[0], np.eye(3)) and not rel.p[0].any()
    custom = relative_from_camera_poses(Trajectory(t, p, q), rot_sigma_deg=1.0, trans_frac=0.5, trans_floor_m=0.01,
                                        gap_factor=3.5)
    assert custom.valid.tolist() == [False, True, True, True, True, True]
    assert custom.cov[2, 3, 3] == pytest.approx((0.5 * 0.2 + 0.01) ** 2, rel=1e-12, abs=0)
    assert custom.cov[2, 0, 0] == pytest.approx(math.radians(1.0) ** 2, rel=1e-12, abs=0)
    with pytest.raises(InvalidDataError, match="^odometry holds fewer than two frames$"):
        relative_from_camera_poses(Trajectory(t[:1], p[:1], q[:1]))
    two = relative_from_camera_poses(Trajectory(t[:2], p[:2], q[:2]))  # two frames are enough
    assert two.valid.tolist() == [False, True]


def test_bytes_that_are_not_utf8_in_a_column_not_read_do_no_harm(tmp_path):
    p = tmp_path / "d.csv"
    p.write_bytes(b"t,distance,note\n0,0,caf\xe9\n1,0.5,\xff\xfe\n")
    t, d = read_wheel_csv(p)
    assert t.tolist() == [0.0, 1.0] and d.tolist() == [0.0, 0.5]


@pytest.mark.parametrize("cuts", [[1, 2, 3, 4, 5], [3], [6]])
def test_camera_motions_as_they_come_are_the_batch_ones_and_judge_gaps_by_the_intervals_so_far(cuts):
    from scipy.spatial.transform import Rotation

    from gpr3d.core.trajectory import Trajectory
    from gpr3d.io.inertial import CameraMotions

    t = np.array([0.0, 0.1, 0.2, 0.3, 0.45, 0.76, 0.86, 1.5])
    ang = np.deg2rad([0, 10, 20, 30, 40, 50, 55, 70])
    q = Rotation.from_euler("zyx", np.c_[ang, 0.5 * ang, -0.3 * ang]).as_quat()[:, [3, 0, 1, 2]]
    p = np.stack([np.arange(8) * 0.2, np.sin(np.arange(8)), np.zeros(8)], 1)
    batch = relative_from_camera_poses(Trajectory(t, p, q))
    cm = CameraMotions()
    parts = [cm.add(t[a:b], p[a:b], q[a:b]) for a, b in zip([0, *cuts], [*cuts, 8])]
    tt, R, pr, cov, valid = (np.concatenate(x) for x in zip(*parts))
    np.testing.assert_array_equal(tt, t)
    # (the same three-term products summed in another order where the chunks differ: a few ulps of terms under
    # 1.5 on any CPU, under 1e-15; 1e-13 leaves room, and a wrong frame pairing or rotation is off by 0.01 or more)
    np.testing.assert_allclose(R, batch.R, rtol=0, atol=1e-13)
    np.testing.assert_allclose(pr, batch.p, rtol=0, atol=1e-13)
    np.testing.assert_allclose(cov, batch.cov, rtol=1e-12, atol=0)
    # the batch judges by the whole record's median (0.1 s); as they come, by the intervals up to each frame:
    # the first (0.1) is its own median; 0.31 s after four of 0.1 and one of 0.15 is a gap, as is 0.64 s
    assert batch.valid.tolist() == [False, True, True, True, True, False, True, False]
    assert valid.dtype == bool and valid.tolist() == [False, True, True, True, True, False, True, False]
    # the median so far, of an even number of intervals the mean of the middle two: 0.4 s after 0.1 s is a gap
    # (1.5 x 0.25), 0.2 after 0.1, 0.1 (median 0.1) too, then 0.2 after 0.1, 0.1, 0.2 is not (1.5 x 0.15), nor 0.29
    # after 0.1, 0.1, 0.2, 0.2 (1.5 x 0.2)
    assert CameraMotions().add([0.0, 0.1, 0.5], p[:3], q[:3])[4].tolist() == [False, True, False]
    tt = [0.0, 0.1, 0.2, 0.4, 0.6, 0.89]
    assert CameraMotions().add(tt, p[:6], q[:6])[4].tolist() == [False, True, True, False, True, True]
    # where the rate rises later, the two differ: 0.16 s after 0.1 is within 1.5x of the median so far (0.13 s),
    # beyond 1.5x the whole record's (0.075 s)
    t = [0.0, 0.1, 0.26, 0.31, 0.36]
    assert relative_from_camera_poses(Trajectory(t, p[:5], q[:5])).valid.tolist() == [False, True, False, True, True]
    _, _, _, _, v = CameraMotions(gap_factor=1.5).add(t, p[:5], q[:5])
    assert v.tolist() == [False, True, True, True, True]
