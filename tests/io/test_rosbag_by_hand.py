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


# ------------------------------------------------------------------------------------------------ image messages

def _raw(img, enc, *, big=False, pad=3):
    """A sensor_msgs/Image stand-in holding ``img`` (h, w[, c]) row by row, each row ``pad`` bytes longer."""
    from types import SimpleNamespace

    a = np.asarray(img)
    a = a.astype(a.dtype.newbyteorder(">" if big else "<"))
    h, w = a.shape[:2]
    rows = a.reshape(h, -1).view(np.uint8).reshape(h, -1)
    data = np.concatenate([rows, np.full((h, pad), 77, np.uint8)], axis=1).ravel()
    return (SimpleNamespace(msgtype="sensor_msgs/msg/Image"),
            SimpleNamespace(encoding=enc, height=h, width=w, step=rows.shape[1] + pad, is_bigendian=int(big),
                            data=data))


@pytest.mark.parametrize("enc, dtype, ch", [("rgb8", np.uint8, 3), ("mono8", np.uint8, 1), ("16UC1", np.uint16, 1),
                                            ("mono16", np.uint16, 1), ("32FC1", np.float32, 1)])
@pytest.mark.parametrize("big", [False, True])
def test_raw_images_decoded_from_padded_rows_in_either_byte_order(enc, dtype, ch, big):
    from gpr3d.io.rosbag import _decode

    rng = np.random.default_rng(3)
    img = (rng.random((4, 5, ch) if ch > 1 else (4, 5)) * 250).astype(dtype)
    got, kind = _decode(*_raw(img, enc, big=big), "/cam")
    np.testing.assert_array_equal(got, img)
    assert got.dtype == np.dtype(dtype) and got.dtype.isnative and kind == enc.lower()


def test_bgr_and_alpha_images_come_out_rgb():
    from gpr3d.io.rosbag import _decode

    rgba = np.arange(4 * 5 * 4, dtype=np.uint8).reshape(4, 5, 4)
    np.testing.assert_array_equal(_decode(*_raw(rgba, "rgba8"), "/c")[0], rgba[..., :3])
    np.testing.assert_array_equal(_decode(*_raw(rgba, "bgra8"), "/c")[0], rgba[..., [2, 1, 0]])
    np.testing.assert_array_equal(_decode(*_raw(rgba[..., :3], "bgr8"), "/c")[0], rgba[..., [2, 1, 0]])


def test_bad_raw_images_are_named_in_full():
    from gpr3d.core.errors import InvalidDataError
    from gpr3d.io.rosbag import _decode

    conn, m = _raw(np.zeros((4, 5), np.uint16), "yuv422")
    with pytest.raises(InvalidDataError) as err:
        _decode(conn, m, "/cam")
    assert str(err.value) == ("/cam: image encoding 'yuv422' is not read (one of ['16uc1', '32fc1', 'bgr8', 'bgra8', "
                              "'mono16', 'mono8', 'rgb8', 'rgba8'])")
    for cut in ({"data": m.data[:-1]}, {"step": 9}):  # a byte short; rows narrower than 5 16-bit pixels
        conn, m = _raw(np.zeros((4, 5), np.uint16), "16UC1")
        for k, v in cut.items():
            setattr(m, k, v)
        with pytest.raises(InvalidDataError) as err:
            _decode(conn, m, "/d")
        assert str(err.value) == "/d: image data shorter than its 4 x 5 16uc1 size (truncated message)"


def test_compressed_images_decoded_by_pillow():
    import io
    from types import SimpleNamespace

    from PIL import Image

    from gpr3d.core.errors import InvalidDataError
    from gpr3d.io.rosbag import _decode

    conn = SimpleNamespace(msgtype="sensor_msgs/msg/CompressedImage")
    rng = np.random.default_rng(4)
    for img, kind in [((rng.random((6, 7, 3)) * 255).astype(np.uint8), "rgb8"),
                      ((rng.random((6, 7)) * 255).astype(np.uint8), "mono8"),
                      ((rng.random((6, 7)) * 60000).astype(np.uint16), "16UC1")]:
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="PNG")
        got, k = _decode(conn, SimpleNamespace(format="png", data=buf.getvalue()), "/c")
        np.testing.assert_array_equal(got, img)
        assert k == kind
    with pytest.raises(InvalidDataError) as err:
        _decode(conn, SimpleNamespace(format="16UC1; compressedDepth png", data=b""), "/d")
    assert str(err.value) == "/d: compressedDepth images are not read; record depth raw (16UC1)"
    with pytest.raises(InvalidDataError) as err:
        _decode(conn, SimpleNamespace(format="jpeg", data=b"not a picture"), "/c")
    assert str(err.value) == "/c: a compressed image (jpeg) that cannot be decoded"


# ------------------------------------------------------------------------------------------------ topics and messages

_POSES = "geometry_msgs/msg/PoseStamped, geometry_msgs/msg/PoseWithCovarianceStamped, nav_msgs/msg/Odometry"
_IMAGES = "sensor_msgs/msg/Image, sensor_msgs/msg/CompressedImage"


def _imu(n, t0=1.0):
    return ImuSamples(t0 + 0.01 * np.arange(n), np.array([[0.1, 0.2, 9.8]]) + 0.01 * np.arange(n)[:, None],
                      0.001 * np.arange(3 * n, dtype=float).reshape(n, 3))


def _frames(times, h=2, w=3):
    return [(t, np.full((h, w, 3), k, np.uint8), np.full((h, w), 100 + k, np.uint16)) for k, t in enumerate(times)]


def _messages_of(path, cases):
    from gpr3d.core.errors import InvalidDataError

    for call, msg in cases:
        with pytest.raises(InvalidDataError) as err:
            call()
        assert str(err.value) == msg.format(path=path)


def test_topics_that_are_missing_or_of_another_type_are_named_in_full(tmp_path):
    from gpr3d.io.rosbag import iter_bag_rgbd, read_bag_camera_info, read_bag_imu, read_bag_trajectory

    imu_only, traj_only, frames = tmp_path / "imu", tmp_path / "traj", tmp_path / "frames"
    write_bag(imu_only, imu=_imu(3))
    write_bag(traj_only, trajectory=Trajectory(np.array([1.0, 2.0]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1))))
    write_bag(frames, frames=_frames([1.0, 2.0]))
    _messages_of(imu_only, [
        (lambda: read_bag_trajectory(imu_only), "{path}: no pose topic (" + _POSES + ")"),
        (lambda: read_bag_trajectory(imu_only, "/imu"), "{path}: topic '/imu' holds sensor_msgs/msg/Imu, not pose ("
         + _POSES + ")"),
        (lambda: read_bag_camera_info(imu_only), "{path}: no camera info topic (sensor_msgs/msg/CameraInfo)"),
        (lambda: read_bag_camera_info(imu_only, "/cam"), "{path}: no topic '/cam' (topics: ['/imu'])"),
        (lambda: list(iter_bag_rgbd(imu_only, None, None)), "{path}: no colour image topic (" + _IMAGES + ")"),
    ])
    _messages_of(traj_only, [(lambda: read_bag_imu(traj_only), "{path}: no IMU topic (sensor_msgs/msg/Imu)")])
    _messages_of(frames, [
        (lambda: list(iter_bag_rgbd(frames, None, "/camera/depth")),
         "{path}: several colour image topics ['/camera/color', '/camera/depth']: name one"),
        (lambda: list(iter_bag_rgbd(frames, "/camera/color", None)),
         "{path}: several depth image topics ['/camera/color', '/camera/depth']: name one"),
        (lambda: list(iter_bag_rgbd(frames, "/camera/color", "/camera/color")),
         "/camera/color: depth must be 16UC1 (mm) or 32FC1 (m), got rgb8"),
    ])


def test_an_imu_topic_needs_two_messages_and_poses_keep_their_times(tmp_path):
    from gpr3d.io.rosbag import read_bag_imu, read_bag_trajectory

    def one(w, ts):
        T = ts.types
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        v = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=9.8)
        m = T["sensor_msgs/msg/Imu"](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="i"),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9), angular_velocity=v, angular_velocity_covariance=np.zeros(9),
            linear_acceleration=v, linear_acceleration_covariance=np.zeros(9))
        w.write(c, 10**9, ts.serialize_cdr(m, "sensor_msgs/msg/Imu"))

    _writer_bag(tmp_path / "one", one)
    _messages_of(tmp_path / "one", [(lambda: read_bag_imu(tmp_path / "one"),
                                     "{path}: the IMU topic holds 1 message(s)")])
    write_bag(tmp_path / "two", imu=_imu(2), trajectory=Trajectory(
        np.array([1.5, 2.75]), np.array([[1.0, 2, 3], [4, 5, 6]]), np.tile([1.0, 0, 0, 0], (2, 1))))
    imu = read_bag_imu(tmp_path / "two")
    np.testing.assert_allclose(imu.t_s, [1.0, 1.01], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(imu.gyro, _imu(2).gyro)
    traj = read_bag_trajectory(tmp_path / "two")
    np.testing.assert_array_equal(traj.timestamps_s, [1.5, 2.75])
    np.testing.assert_array_equal(traj.positions_xyz, [[1.0, 2, 3], [4, 5, 6]])


def _writer_bag(path, write):
    """A ROS 2 bag written with rosbags' own writer: ``write(writer, typestore)`` adds what it needs."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(path, version=8) as w:
        write(w, ts)
    return ts


def test_topics_without_messages_are_named(tmp_path):
    from gpr3d.io.rosbag import iter_bag_rgbd, read_bag_camera_info, read_bag_trajectory

    def empty(w, ts):
        for topic, kind in [("/pose", "geometry_msgs/msg/PoseStamped"), ("/info", "sensor_msgs/msg/CameraInfo"),
                            ("/c", "sensor_msgs/msg/Image"), ("/d", "sensor_msgs/msg/Image")]:
            w.add_connection(topic, kind, typestore=ts)

    path = tmp_path / "empty"
    _writer_bag(path, empty)
    _messages_of(path, [
        (lambda: read_bag_trajectory(path), "{path}: the pose topic holds no message"),
        (lambda: read_bag_camera_info(path), "{path}: the camera info topic holds no message"),
        (lambda: list(iter_bag_rgbd(path, "/c", "/d")), "{path}: the colour topic holds no image"),
    ])


def test_odometry_poses_are_read_from_their_pose_with_covariance(tmp_path):
    from gpr3d.io.rosbag import read_bag_trajectory

    def odom(w, ts):
        T = ts.types
        c = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        for k, t in enumerate((1.25, 2.5)):
            hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=int(
                round((t - int(t)) * 1e9))), frame_id="odom")
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=1.0 + k, y=2.0, z=3.0),
                                               orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                             w=1.0))
            cov = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
            twist = T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](
                linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36))
            m = T["nav_msgs/msg/Odometry"](header=hdr, child_frame_id="base", pose=cov, twist=twist)
            w.write(c, int(t * 1e9), ts.serialize_cdr(m, "nav_msgs/msg/Odometry"))

    _writer_bag(tmp_path / "o", odom)
    traj = read_bag_trajectory(tmp_path / "o")
    np.testing.assert_array_equal(traj.timestamps_s, [1.25, 2.5])
    np.testing.assert_array_equal(traj.positions_xyz, [[1.0, 2.0, 3.0], [2.0, 2.0, 3.0]])


def test_depth_pairs_within_20_ms_and_metres_clipped_to_16_bits(tmp_path):
    from gpr3d.io.rosbag import iter_bag_rgbd

    def images(w, ts):
        T = ts.types
        cc = w.add_connection("/c", "sensor_msgs/msg/Image", typestore=ts)
        cd = w.add_connection("/d", "sensor_msgs/msg/Image", typestore=ts)

        def img(t, enc, data, step):
            hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=int(
                round((t - int(t)) * 1e9))), frame_id="c")
            return ts.serialize_cdr(T["sensor_msgs/msg/Image"](header=hdr, height=1, width=3, encoding=enc,
                                                               is_bigendian=0, step=step, data=data),
                                    "sensor_msgs/msg/Image")

        for k, t in enumerate((1.0, 2.0)):
            w.write(cc, int(t * 1e9), img(t, "mono8", np.full(3, k, np.uint8), 3))
        depth = np.array([0.5, 70.0, -1.0], np.float32).view(np.uint8)
        for t in (1.03, 2.01):  # 30 ms from its colour image: left out; 10 ms: paired
            w.write(cd, int(t * 1e9), img(t, "32FC1", depth, 12))

    _writer_bag(tmp_path / "i", images)
    (t, colour, depth), = list(iter_bag_rgbd(tmp_path / "i", "/c", "/d"))
    assert t == pytest.approx(2.01, abs=1e-9)
    np.testing.assert_array_equal(colour, [[1, 1, 1]])
    np.testing.assert_array_equal(depth, [[500, 65535, 0]])
    assert depth.dtype == np.uint16
    assert len(list(iter_bag_rgbd(tmp_path / "i", "/c", "/d", max_dt_s=0.05))) == 2


def test_bags_that_cannot_be_read_are_named(tmp_path, monkeypatch):
    import sys

    from rosbags.highlevel import AnyReader

    from gpr3d.core.errors import FormatError, GPR3DError
    from gpr3d.io.rosbag import read_bag_imu

    broken = tmp_path / "broken.bag"
    broken.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 40)
    with pytest.raises(FormatError) as err:
        read_bag_imu(broken)
    with pytest.raises(Exception) as direct:
        AnyReader([broken]).open()
    first = str(direct.value).splitlines()[0] if str(direct.value) else ""
    assert str(err.value) == f"broken.bag: not a readable ROS bag ({type(direct.value).__name__}: {first})"
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # as if rosbags were not installed
    with pytest.raises(GPR3DError) as err:
        read_bag_imu(broken)
    assert str(err.value) == "reading ROS bags needs rosbags: pip install 'gpr3d[pose]'"


def test_written_headers_carry_the_frame_and_the_nanosecond(tmp_path):
    write_bag(tmp_path / "h", imu=_imu(2, t0=1.75))
    (_, _, _, m0), (_, _, _, m1) = _read(tmp_path / "h", False)
    assert (m0.header.stamp.sec, m0.header.stamp.nanosec, m0.header.frame_id) == (1, 750000000, "camera")
    assert (m1.header.stamp.sec, m1.header.stamp.nanosec) == (1, 760000000)
    assert "version: 8" in (tmp_path / "h" / "metadata.yaml").read_text()
