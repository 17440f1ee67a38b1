"""``write_bag`` read back field by field with rosbags' own reader (not ours): every message's header, the IMU's
unknown orientation, the images' encodings, steps and bytes, the camera info's matrices, and the bag's time order."""

import numpy as np
import pytest

pytest.importorskip("rosbags")

from gpr3d.core.inertial import ImuSamples  # noqa: E402
from gpr3d.core.trajectory import Trajectory  # noqa: E402
from gpr3d.io.rosbag import write_bag  # noqa: E402
from gpr3d.pose.render import CameraIntrinsics  # noqa: E402


def _read(path, ros1):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = []
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    with AnyReader([path], default_typestore=ts) as r:
        for conn, t, raw in r.messages():
            out.append((conn.topic, conn.msgtype, t, r.deserialize(raw, conn.msgtype)))
    return out


@pytest.mark.parametrize("ros1", [False, True])
def test_every_field_written_as_ros_tools_read_it(tmp_path, ros1):
    imu = ImuSamples(np.array([0.25, 1.5]), np.array([[0.1, 0.2, 9.8], [0.3, 0.4, 9.7]]),
                     np.array([[0.01, 0.02, 0.03], [0.04, 0.05, 0.06]]))
    traj = Trajectory(np.array([0.5, 2.0]), np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]),
                      np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]))
    colour = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    depth = np.array([[1, 2, 3], [300, 65535, 0]], np.uint16)
    intr = CameraIntrinsics(fx=100.0, fy=110.0, cx=1.5, cy=0.75, width=3, height=2)
    path = tmp_path / ("b.bag" if ros1 else "b2")
    write_bag(path, imu=imu, trajectory=traj, frames=[(1.0, colour, depth)], intrinsics=intr, ros1=ros1,
              frame_id="rig")
    msgs = _read(path, ros1)
    # in time order, each stamped 1 ns after its time (0 s: 1 ns)
    assert [(m[0], m[2]) for m in msgs] == [("/camera/info", 1), ("/imu", 250_000_001), ("/odometry", 500_000_001),
                                            ("/camera/color", 1_000_000_001), ("/camera/depth", 1_000_000_001),
                                            ("/imu", 1_500_000_001), ("/odometry", 2_000_000_001)]
    stamps = [(m[3].header.stamp.sec, m[3].header.stamp.nanosec) for m in msgs]
    assert stamps == [(0, 0), (0, 250_000_000), (0, 500_000_000), (1, 0), (1, 0), (1, 500_000_000), (2, 0)]
    assert {m[3].header.frame_id for m in msgs} == {"rig"}
    if ros1:
        assert {m[3].header.seq for m in msgs} == {0}
    info = msgs[0][3]
    k, p, d, r = (info.K, info.P, info.D, info.R) if ros1 else (info.k, info.p, info.d, info.r)
    np.testing.assert_array_equal(k, [100.0, 0, 1.5, 0, 110.0, 0.75, 0, 0, 1])
    np.testing.assert_array_equal(p, [100.0, 0, 1.5, 0, 0, 110.0, 0.75, 0, 0, 0, 1, 0])
    np.testing.assert_array_equal(d, np.zeros(5))
    np.testing.assert_array_equal(r, np.eye(3).reshape(-1))
    assert (info.height, info.width, info.distortion_model, info.binning_x, info.binning_y) == (2, 3, "plumb_bob", 0, 0)
    roi = info.roi
    assert (roi.x_offset, roi.y_offset, roi.height, roi.width, roi.do_rectify) == (0, 0, 0, 0, False)
    m = msgs[1][3]
    o = m.orientation
    assert (o.x, o.y, o.z, o.w) == (0.0, 0.0, 0.0, 1.0)  # no orientation estimate
    assert (m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z) == (0.1, 0.2, 9.8)
    assert (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) == (0.01, 0.02, 0.03)
    for cov in (m.orientation_covariance, m.angular_velocity_covariance, m.linear_acceleration_covariance):
        np.testing.assert_array_equal(cov, np.zeros(9))
    pose = msgs[6][3].pose
    assert (pose.position.x, pose.position.y, pose.position.z) == (4.0, 5.0, 6.0)
    assert (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w) == (1.0, 0.0, 0.0, 0.0)
    c, dd = msgs[3][3], msgs[4][3]
    assert (c.encoding, c.step, c.height, c.width, c.is_bigendian) == ("rgb8", 9, 2, 3, 0)
    assert bytes(c.data) == colour.tobytes()
    assert (dd.encoding, dd.step, dd.height, dd.width, dd.is_bigendian) == ("16UC1", 6, 2, 3, 0)
    assert bytes(dd.data) == depth.astype("<u2").tobytes()
