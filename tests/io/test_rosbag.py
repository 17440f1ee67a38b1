"""ROS 1 and ROS 2 bags written with rosbags and read back; the pipeline from a bag to fused poses."""

import re
import shutil

import numpy as np
import pytest

pytest.importorskip("rosbags")

from gpr3d.core.errors import FormatError, GPR3DError, InvalidDataError  # noqa: E402
from gpr3d.io.rosbag import (TRACE_TYPE, bag_topics, iter_bag_rgbd, iter_bag_traces,  # noqa: E402
                             read_bag_camera_info, read_bag_imu, read_bag_trajectory, write_bag)
from gpr3d.pose.render import CameraIntrinsics, FloorScene, render_rgbd, rig_camera_poses  # noqa: E402
from gpr3d.pose.rig import RigConfig, simulate_rig  # noqa: E402


@pytest.fixture(scope="module")
def run():
    return simulate_rig(RigConfig(duration_s=10, still_start_s=1.0, still_end_s=1.0), seed=3)


@pytest.mark.parametrize("ros1", [False, True])
def test_bag_round_trip_keeps_every_value(tmp_path, run, ros1):
    intr = CameraIntrinsics.d435i(48)
    T = rig_camera_poses(run, run.vo.t_s[:4])
    frames = [(run.vo.t_s[k],) + render_rgbd(FloorScene(seed=1), intr, T[k], rng=np.random.default_rng(k))
              for k in range(4)]
    traj = run.truth_trajectory(run.vo.t_s)
    path = tmp_path / ("r.bag" if ros1 else "r2")
    write_bag(path, imu=run.imu, trajectory=traj, frames=frames, intrinsics=intr, ros1=ros1)
    topics = {t: (m, n) for t, m, n in bag_topics(path)}
    assert topics["/imu"] == ("sensor_msgs/msg/Imu", run.imu.t_s.size)
    imu = read_bag_imu(path)
    np.testing.assert_allclose(imu.t_s, run.imu.t_s, atol=1e-9)  # stamps to the nanosecond
    np.testing.assert_array_equal(imu.accel, run.imu.accel)
    np.testing.assert_array_equal(imu.gyro, run.imu.gyro)
    back = read_bag_trajectory(path, "/odometry")
    np.testing.assert_array_equal(back.positions_xyz, traj.positions_xyz)
    q, q0 = back.orientations_quat_wxyz, traj.orientations_quat_wxyz
    assert np.allclose(np.abs(np.sum(q * q0, axis=1)), 1.0)
    assert read_bag_camera_info(path) == intr
    got = list(iter_bag_rgbd(path, "/camera/color", "/camera/depth"))
    assert len(got) == 4
    for (t, c, d), (t0, c0, d0) in zip(got, frames):
        assert abs(t - t0) < 1e-9 and np.array_equal(c, c0) and np.array_equal(d, d0) and d.dtype == np.uint16


def test_bad_bags_and_topics_give_one_line(tmp_path, run):
    path = tmp_path / "b"
    write_bag(path, imu=run.imu)
    with pytest.raises(InvalidDataError, match="no pose topic"):
        read_bag_trajectory(path)
    with pytest.raises(InvalidDataError, match="holds sensor_msgs/msg/Imu, not pose"):
        read_bag_trajectory(path, "/imu")
    with pytest.raises(InvalidDataError, match="no topic '/cam'"):
        read_bag_imu(path, "/cam")
    broken = tmp_path / "broken.bag"
    broken.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 40)  # a ROS 1 header and nothing readable after it
    with pytest.raises(FormatError, match="not a readable ROS bag"):
        read_bag_imu(broken)
    with pytest.raises(Exception, match="no such bag"):
        read_bag_imu(tmp_path / "missing.bag")


def test_bgr_and_float_depth_images_are_decoded(tmp_path):
    """Images as other drivers write them: bgr8 colour and 32FC1 depth in metres."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    colour = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    depth = np.array([[0.5, 1.25, np.nan], [2.0, 0.0, 3.001]], dtype=np.float32)
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="c")
    with Writer(tmp_path / "w", version=8) as w:
        cc = w.add_connection("/c", "sensor_msgs/msg/Image", typestore=ts)
        cd = w.add_connection("/d", "sensor_msgs/msg/Image", typestore=ts)
        w.write(cc, 1, ts.serialize_cdr(T["sensor_msgs/msg/Image"](
            header=hdr, height=2, width=3, encoding="bgr8", is_bigendian=0, step=9,
            data=colour[..., ::-1].copy().reshape(-1)), "sensor_msgs/msg/Image"))
        w.write(cd, 2, ts.serialize_cdr(T["sensor_msgs/msg/Image"](
            header=hdr, height=2, width=3, encoding="32FC1", is_bigendian=0, step=12,
            data=depth.view(np.uint8).reshape(-1)), "sensor_msgs/msg/Image"))
    (t, c, d), = list(iter_bag_rgbd(tmp_path / "w", "/c", "/d"))
    assert t == 1.0 and np.array_equal(c, colour)
    np.testing.assert_array_equal(d, [[500, 1250, 0], [2000, 0, 3001]])


def test_rgbd_bag_to_fused_antenna_poses(tmp_path, run, capsys):
    """The whole path from a bag: IMU and RGB-D frames in, Open3D odometry, the filter, a TUM file out close to
    the truth."""
    pytest.importorskip("open3d", exc_type=ImportError)
    from gpr3d.cli.main import main
    from gpr3d.io.inertial import write_rig
    from gpr3d.io.trajectory import read_tum, write_tum
    from gpr3d.pose.metrics import ape

    intr = CameraIntrinsics.d435i(240)
    tc = run.vo.t_s
    T = rig_camera_poses(run, tc + run.config.camera_time_offset_s)
    scene = FloorScene.random(seed=3)
    rng = np.random.default_rng(0)
    frames = ((tc[k],) + render_rgbd(scene, intr, T[k], rng=rng) for k in range(tc.size))
    write_bag(tmp_path / "bag", imu=run.imu, frames=frames, intrinsics=intr)
    cfg = run.config
    write_rig(tmp_path / "rig.json", imu_T_camera=cfg.imu_T_camera, imu_T_antenna=cfg.imu_T_antenna,
              camera_time_offset_s=cfg.camera_time_offset_s)
    write_tum(run.truth_trajectory(), tmp_path / "truth.tum")
    assert main(["pose", "fuse", "--bag", str(tmp_path / "bag"), "--colour-topic", "/camera/color", "--depth-topic",
                 "/camera/depth", "--rig", str(tmp_path / "rig.json"), "--still", "0.8", "--smooth", "--loops",
                 "--out", str(tmp_path / "a.tum")]) == 0
    assert "loop closures: 0 registered of 0 revisits" in capsys.readouterr().out  # 10 s: nothing revisited
    est = read_tum(tmp_path / "a.tum")
    assert ape(est, run.truth_trajectory())["rmse"] < 0.01 * run.path_length_m
    shutil.rmtree(tmp_path / "bag")


@pytest.mark.parametrize("ros1", [False, True])
def test_gpr_traces_round_trip_one_or_several_a_message(tmp_path, ros1):
    rng = np.random.default_rng(5)
    t = 100.0 + 0.01 * np.arange(6) + 1e-9 * rng.integers(0, 1000, 6)
    data = rng.standard_normal((6, 8)).astype(np.float32)
    path = tmp_path / ("g.bag" if ros1 else "g2")
    write_bag(path, traces=(t, data), ros1=ros1)
    assert [(tp, m) for tp, m, _ in bag_topics(path)] == [("/gpr/traces", TRACE_TYPE)]
    got = list(iter_bag_traces(path))  # (the one topic whose type names a trace)
    assert len(got) == 6
    np.testing.assert_allclose([g[0] for g in got], t, atol=1e-9, rtol=0)
    np.testing.assert_array_equal(np.concatenate([g[1] for g in got]), data)
    # a message of two traces of 4 samples each, one after the other
    two = list(iter_bag_traces(path, "/gpr/traces", samples_per_trace=4))
    assert all(g[1].shape == (2, 4) for g in two)
    np.testing.assert_array_equal(np.concatenate([g[1] for g in two]), data.reshape(12, 4))


@pytest.mark.parametrize("msgtype, found", [
    ("radar_pkg/msg/RadarTrace", True), ("sensors/msg/GPRScan", True), ("husky_gpr/msg/GPRTrace", True),
    ("gpr_msgs/msg/Scan", False),  # (the package's name does not count: the type's own)
])
def test_the_trace_topic_is_found_by_its_type_s_name(tmp_path, run, msgtype, found):
    path = tmp_path / "f"
    t = np.arange(3) * 0.1 + 1.0
    write_bag(path, imu=run.imu, traces={"/radar/a": (t, np.ones((3, 4)))}, trace_type=msgtype)
    if found:
        got = list(iter_bag_traces(path))  # (the IMU's messages left alone)
        assert [g[1].shape for g in got] == [(1, 4)] * 3
    else:
        with pytest.raises(InvalidDataError, match="no GPR trace topic"):
            list(iter_bag_traces(path))
    two = tmp_path / "two"
    write_bag(two, traces={"/a": (t, np.ones((3, 4))), "/b": (t, np.ones((3, 4)))})
    with pytest.raises(InvalidDataError, match=r"several GPR trace topics \['/a', '/b'\]: name the topic"):
        list(iter_bag_traces(two))
    assert len(list(iter_bag_traces(two, "/b", samples_per_trace=2))) == 3  # (2 samples a trace: the fewest)


def test_gpr_trace_bags_that_cannot_be_read_give_one_line(tmp_path, run):
    path = tmp_path / "u"
    write_bag(path, traces=([0.0, 0.1], [np.zeros(4), np.zeros(5)]))  # a trace of 5 samples after one of 4
    with pytest.raises(InvalidDataError, match="message 1 holds 5 samples where the traces have 4 "
                                               r"\(several traces a message: give the samples per trace\)"):
        list(iter_bag_traces(path))
    with pytest.raises(InvalidDataError, match="message 0 holds 4 samples where the traces have 3$"):
        list(iter_bag_traces(path, samples_per_trace=3))
    with pytest.raises(GPR3DError, match="samples per trace must be a whole number of at least 2, got 1"):
        iter_bag_traces(path, samples_per_trace=1)
    nan = tmp_path / "n"
    write_bag(nan, traces=([0.0, 0.1], [np.zeros(4), np.array([0, np.nan, 0, 0])]))
    with pytest.raises(InvalidDataError, match="/gpr/traces: message 1 holds non-finite samples"):
        list(iter_bag_traces(nan))
    imu = tmp_path / "i"
    write_bag(imu, imu=run.imu)
    with pytest.raises(InvalidDataError, match="no GPR trace topic"):
        iter_bag_traces(imu)  # (named when asked, before any message is read)
    with pytest.raises(InvalidDataError, match=r"/imu: its messages \(sensor_msgs/msg/Imu\) hold no header and "
                                               "numeric array named trace, samples, data"):
        list(iter_bag_traces(imu, "/imu"))
    with pytest.raises(InvalidDataError, match=re.escape(f"{imu}: no topic '/gpr'")):
        list(iter_bag_traces(imu, "/gpr"))
