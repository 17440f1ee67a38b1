"""ROS 1 and ROS 2 bags through ``rosbags`` (no ROS installation needed): IMU, poses, camera images.

Read from a bag (a ROS 1 ``.bag`` file or a ROS 2 bag folder):

* ``sensor_msgs/Imu`` -> :class:`gpr3d.core.inertial.ImuSamples` (:func:`read_bag_imu`);
* ``geometry_msgs/PoseStamped``, ``geometry_msgs/PoseWithCovarianceStamped``, ``nav_msgs/Odometry`` ->
  :class:`~gpr3d.core.trajectory.Trajectory` (:func:`read_bag_trajectory`): visual odometry's camera poses, or a
  reference;
* ``sensor_msgs/CameraInfo`` -> :class:`gpr3d.core.camera.CameraIntrinsics` (:func:`read_bag_camera_info`);
* GPR traces (a message with a ``header`` and the samples in a float array named ``trace``, ``samples`` or
  ``data``: the layout of ``GPRTrace`` of a ROS 1 driver of the Noggin radar, and of gpr3d's own
  ``gpr_msgs/msg/GPRTrace``, ``TRACE_MSG``) -> ``(t, traces)`` per message (:func:`iter_bag_traces`): what
  ``gpr3d live`` replays from a bag;
* ``sensor_msgs/Image`` and ``sensor_msgs/CompressedImage`` (colour: ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``,
  ``mono8``, JPEG/PNG; depth: ``16UC1`` millimetres or ``32FC1`` metres) -> ``(t, colour, depth)`` frames for
  :func:`gpr3d.pose.vo.rgbd_odometry`, colour and depth paired by the nearest stamp (:func:`iter_bag_rgbd`).

Times are the messages' header stamps (the sensor's clock), in seconds. A topic left out is found by its
message type when the bag holds exactly one of that type (a trace topic: one whose type's name holds ``Trace`` or
``GPR``); otherwise the error lists the candidates. A ROS 2 bag must hold its message definitions for a type
outside the standard ones (rosbag2 does from Iron on, and with MCAP storage); a ROS 1 bag always does.
``rosbags`` is an optional extra (``pip install 'gpr3d[pose]'``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError, GPR3DError, InvalidDataError
from gpr3d.core.trajectory import Trajectory

__all__ = ["TRACE_MSG", "TRACE_TYPE", "bag_topics", "read_bag_imu", "read_bag_trajectory", "read_bag_camera_info",
           "iter_bag_rgbd", "iter_bag_traces", "write_bag"]

_IMU = ("sensor_msgs/msg/Imu",)
_POSE = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry")
_INFO = ("sensor_msgs/msg/CameraInfo",)
_IMAGE = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")


#: gpr3d's trace message type (one trace a message; several: ``samples_per_trace``)
TRACE_TYPE = "gpr_msgs/msg/GPRTrace"
#: its definition: a header and the samples
TRACE_MSG = "std_msgs/Header header\nfloat32[] trace\n"
_TRACE_FIELDS = ("trace", "samples", "data")


def _reader(path):
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise GPR3DError("reading ROS bags needs rosbags: pip install 'gpr3d[pose]'") from None
    p = Path(path)
    if not p.exists():
        raise GPR3DError(f"{p}: no such bag (a ROS 1 .bag file or a ROS 2 bag folder)")
    try:
        reader = AnyReader([p])
        reader.open()
    except Exception as exc:  # rosbags raises its own errors for unreadable, truncated or unknown bags
        raise FormatError(p, f"not a readable ROS bag ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    return reader


def bag_topics(path) -> list[tuple[str, str, int]]:
    """``(topic, message type, count)`` of every topic in the bag."""
    r = _reader(path)
    try:
        return sorted((c.topic, c.msgtype, c.msgcount) for c in r.connections)
    finally:
        r.close()


def _pick(r, path, topic, types, what):
    if topic is not None:
        conns = [c for c in r.connections if c.topic == topic]
        if not conns:
            raise InvalidDataError(f"{path}: no topic {topic!r} (topics: {sorted({c.topic for c in r.connections})})")
        if conns[0].msgtype not in types:
            raise InvalidDataError(f"{path}: topic {topic!r} holds {conns[0].msgtype}, not {what} ({', '.join(types)})")
        return conns
    conns = [c for c in r.connections if c.msgtype in types]
    names = sorted({c.topic for c in conns})
    if not names:
        raise InvalidDataError(f"{path}: no {what} topic ({', '.join(types)})")
    if len(names) > 1:
        raise InvalidDataError(f"{path}: several {what} topics {names}: name one")
    return conns


def _stamp(msg) -> float:
    return float(msg.header.stamp.sec) + 1e-9 * float(msg.header.stamp.nanosec)


def _messages(r, conns):
    for conn, _, raw in r.messages(connections=conns):
        yield conn, r.deserialize(raw, conn.msgtype)


def read_bag_imu(path, topic: str | None = None):
    """IMU samples (specific force m/s^2, rates rad/s; units are checked by ``ImuSamples``)."""
    from gpr3d.core.inertial import ImuSamples

    r = _reader(path)
    try:
        rows = []
        for _, m in _messages(r, _pick(r, path, topic, _IMU, "IMU")):
            a, w = m.linear_acceleration, m.angular_velocity
            rows.append((_stamp(m), a.x, a.y, a.z, w.x, w.y, w.z))
    finally:
        r.close()
    if len(rows) < 2:
        raise InvalidDataError(f"{path}: the IMU topic holds {len(rows)} message(s)")
    arr = np.array(sorted(rows))
    return ImuSamples(arr[:, 0], arr[:, 1:4], arr[:, 4:7])


def read_bag_trajectory(path, topic: str | None = None) -> Trajectory:
    """Poses of a PoseStamped, PoseWithCovarianceStamped or Odometry topic (its frame: ``header.frame_id``)."""
    r = _reader(path)
    try:
        rows = []
        for conn, m in _messages(r, _pick(r, path, topic, _POSE, "pose")):
            pose = m.pose if conn.msgtype == "geometry_msgs/msg/PoseStamped" else m.pose.pose
            q, p = pose.orientation, pose.position
            rows.append((_stamp(m), p.x, p.y, p.z, q.w, q.x, q.y, q.z))
    finally:
        r.close()
    if not rows:
        raise InvalidDataError(f"{path}: the pose topic holds no message")
    arr = np.array(sorted(rows))
    return Trajectory(arr[:, 0], arr[:, 1:4], arr[:, 4:8])


def read_bag_camera_info(path, topic: str | None = None):
    """The pinhole of the first CameraInfo message (its ``K`` matrix and image size)."""
    from gpr3d.core.camera import CameraIntrinsics

    r = _reader(path)
    try:
        for _, m in _messages(r, _pick(r, path, topic, _INFO, "camera info")):
            K = np.asarray(m.k if hasattr(m, "k") else m.K, dtype=float).reshape(3, 3)
            return CameraIntrinsics(int(m.width), int(m.height), *(float(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2])))
    finally:
        r.close()
    raise InvalidDataError(f"{path}: the camera info topic holds no message")


def _decode(conn, m, topic):
    if conn.msgtype == "sensor_msgs/msg/CompressedImage":
        import io as _io

        from PIL import Image

        if "compresseddepth" in str(m.format).lower():
            raise InvalidDataError(f"{topic}: compressedDepth images are not read; record depth raw (16UC1)")
        try:
            img = np.asarray(Image.open(_io.BytesIO(bytes(m.data))))
        except Exception:
            raise InvalidDataError(f"{topic}: a compressed image ({m.format}) that cannot be decoded") from None
        return img, "rgb8" if img.ndim == 3 else ("16UC1" if img.dtype == np.uint16 else "mono8")
    enc = str(m.encoding).lower()
    h, w, step = int(m.height), int(m.width), int(m.step)
    kinds = {"rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3), "rgba8": (np.uint8, 4), "bgra8": (np.uint8, 4),
             "mono8": (np.uint8, 1), "16uc1": (np.uint16, 1), "mono16": (np.uint16, 1), "32fc1": (np.float32, 1)}
    if enc not in kinds:
        raise InvalidDataError(f"{topic}: image encoding {m.encoding!r} is not read (one of {sorted(kinds)})")
    dt, ch = kinds[enc]
    dt = np.dtype(dt).newbyteorder(">" if m.is_bigendian else "<")
    buf = np.asarray(m.data, dtype=np.uint8)
    if buf.size < h * step or step < w * ch * dt.itemsize:
        raise InvalidDataError(f"{topic}: image data shorter than its {h} x {w} {enc} size (truncated message)")
    img = buf[: h * step].reshape(h, step)[:, : w * ch * dt.itemsize].copy().view(dt).reshape(h, w, ch)
    img = img[..., 0] if ch == 1 else img
    if enc.startswith("bgr"):
        img = img[..., [2, 1, 0]]
    elif enc == "rgba8":
        img = img[..., :3]
    return img.astype(dt.newbyteorder("=")), enc


def iter_bag_rgbd(path, colour_topic: str, depth_topic: str, *, max_dt_s: float = 0.02):
    """``(t, colour, depth)`` frames: each depth image with the colour image nearest in time (within
    ``max_dt_s``; a depth image without one is skipped). Depth in millimetres (``uint16``); ``32FC1`` metres are
    converted."""
    r = _reader(path)
    try:
        cc = _pick(r, path, colour_topic, _IMAGE, "colour image")
        dc = _pick(r, path, depth_topic, _IMAGE, "depth image")
        colour = [(_stamp(m), conn, m) for conn, m in _messages(r, cc)]
        if not colour:
            raise InvalidDataError(f"{path}: the colour topic holds no image")
        ct = np.array([c[0] for c in colour])
        for conn, m in _messages(r, dc):
            t = _stamp(m)
            i = int(np.argmin(np.abs(ct - t)))
            if abs(ct[i] - t) > max_dt_s:
                continue
            depth, enc = _decode(conn, m, depth_topic)
            if enc == "32fc1":
                depth = np.where(np.isfinite(depth), np.round(depth * 1000.0), 0).clip(0, 65535).astype(np.uint16)
            elif depth.dtype != np.uint16:
                raise InvalidDataError(f"{depth_topic}: depth must be 16UC1 (mm) or 32FC1 (m), got {enc}")
            img, _ = _decode(colour[i][1], colour[i][2], colour_topic)
            yield t, img, depth
    finally:
        r.close()


def _pick_traces(r, path, topic):
    if topic is not None:
        conns = [c for c in r.connections if c.topic == topic]
        if not conns:
            raise InvalidDataError(f"{path}: no topic {topic!r} (topics: {sorted({c.topic for c in r.connections})})")
        return conns
    name = lambda c: c.msgtype.rsplit("/", 1)[-1].lower()  # noqa: E731
    conns = [c for c in r.connections if "trace" in name(c) or "gpr" in name(c)]
    names = sorted({c.topic for c in conns})
    if len(names) != 1:
        what = f"several GPR trace topics {names}" if names else "no GPR trace topic (a type named *Trace* or *GPR*)"
        raise InvalidDataError(f"{path}: {what}: name the topic (topics: "
                               f"{sorted((c.topic, c.msgtype) for c in r.connections)})")
    return conns


def iter_bag_traces(path, topic: str | None = None, *, samples_per_trace: int | None = None):
    """``(t, traces)`` for each message of a GPR trace topic, in the bag's order: its header stamp (s) and its
    samples as float32 ``(k, n_samples)``: one trace a message, or ``k`` traces one after another when
    ``samples_per_trace`` is given (all at the message's stamp). Every message must hold the same number of
    samples (or whole multiples of ``samples_per_trace``), all finite."""
    if samples_per_trace is not None and (int(samples_per_trace) != samples_per_trace or samples_per_trace < 2):
        raise GPR3DError(f"samples per trace must be a whole number of at least 2, got {samples_per_trace!r}")
    r = _reader(path)  # (the bag and its topic checked now; the messages read as they are asked for)
    try:
        topic = _pick_traces(r, path, topic)[0].topic
    finally:
        r.close()
    return _trace_messages(path, topic, samples_per_trace)


def _trace_messages(path, topic, samples_per_trace):
    r = _reader(path)
    try:
        conns = [c for c in r.connections if c.topic == topic]
        where = f"{path}: {topic}"
        n = samples_per_trace
        for i, (_, m) in enumerate(_messages(r, conns)):
            arr = next((getattr(m, f) for f in _TRACE_FIELDS if isinstance(getattr(m, f, None), np.ndarray)), None)
            if arr is None or not hasattr(m, "header") or arr.dtype.kind not in "fiu":
                raise InvalidDataError(f"{where}: its messages ({conns[0].msgtype}) hold no header and numeric "
                                       f"array named {', '.join(_TRACE_FIELDS)}")
            n = n or arr.size
            if arr.size == 0 or arr.size % n:
                raise InvalidDataError(f"{where}: message {i} holds {arr.size} samples where the traces have {n}"
                                       + ("" if samples_per_trace else " (several traces a message: give the "
                                                                       "samples per trace)"))
            a = arr.astype(np.float32).reshape(-1, n)
            if not np.all(np.isfinite(a)):
                raise InvalidDataError(f"{where}: message {i} holds non-finite samples")
            yield _stamp(m), a
    finally:
        r.close()


def write_bag(path, *, imu=None, trajectory: Trajectory | None = None, frames=None, intrinsics=None,
              traces=None, trace_type: str = TRACE_TYPE, ros1: bool = False, frame_id: str = "camera") -> None:
    """Write a small bag (ROS 2 folder, or a ROS 1 ``.bag`` with ``ros1=True``): ``/imu`` (Imu), ``/odometry``
    (PoseStamped), ``/camera/color`` and ``/camera/depth`` (Image: rgb8, 16UC1) with ``/camera/info``
    (CameraInfo), ``/gpr/traces`` (``trace_type``, laid out as ``TRACE_MSG``: one message per trace of
    ``traces = (t_s, data)``, or ``{topic: (t_s, data)}`` for several topics). For tests, examples and handing
    synthetic runs to ROS tools."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(TRACE_MSG, trace_type))
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]

    def header(t):
        sec = int(np.floor(t))
        if ros1:
            return Header(seq=0, stamp=Time(sec=sec, nanosec=int(round((t - sec) * 1e9))), frame_id=frame_id)
        return Header(stamp=Time(sec=sec, nanosec=int(round((t - sec) * 1e9))), frame_id=frame_id)

    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(Path(path))
    else:
        from rosbags.rosbag2 import Writer

        writer = Writer(Path(path), version=8)
    ser = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    with writer:
        msgs = []
        if imu is not None:
            c = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
            z9 = np.zeros(9)
            for t, a, w in zip(imu.t_s, imu.accel, imu.gyro):
                m = T["sensor_msgs/msg/Imu"](header=header(t), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                                             orientation_covariance=z9, angular_velocity=V3(x=w[0], y=w[1], z=w[2]),
                                             angular_velocity_covariance=z9,
                                             linear_acceleration=V3(x=a[0], y=a[1], z=a[2]),
                                             linear_acceleration_covariance=z9)
                msgs.append((t, c, ser(m, "sensor_msgs/msg/Imu")))
        if trajectory is not None:
            c = writer.add_connection("/odometry", "geometry_msgs/msg/PoseStamped", typestore=ts)
            P, Pose = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Pose"]
            for t, p, q in zip(trajectory.timestamps_s, trajectory.positions_xyz, trajectory.orientations_quat_wxyz):
                m = T["geometry_msgs/msg/PoseStamped"](header=header(t), pose=Pose(
                    position=P(x=p[0], y=p[1], z=p[2]), orientation=Q(x=q[1], y=q[2], z=q[3], w=q[0])))
                msgs.append((t, c, ser(m, "geometry_msgs/msg/PoseStamped")))
        if frames is not None:
            cc = writer.add_connection("/camera/color", "sensor_msgs/msg/Image", typestore=ts)
            cd = writer.add_connection("/camera/depth", "sensor_msgs/msg/Image", typestore=ts)
            Image = T["sensor_msgs/msg/Image"]
            for t, colour, depth in frames:
                h, w = depth.shape
                kw = {"header": header(t), "height": h, "width": w, "is_bigendian": 0}
                msgs.append((t, cc, ser(Image(encoding="rgb8", step=3 * w,
                                              data=np.ascontiguousarray(colour, np.uint8).reshape(-1), **kw),
                                        "sensor_msgs/msg/Image")))
                msgs.append((t, cd, ser(Image(encoding="16UC1", step=2 * w,
                                              data=np.ascontiguousarray(depth, "<u2").view(np.uint8).reshape(-1), **kw),
                                        "sensor_msgs/msg/Image")))
        for topic, (times, rows) in (traces if isinstance(traces, dict) else
                                     {} if traces is None else {"/gpr/traces": traces}).items():
            c = writer.add_connection(topic, trace_type, typestore=ts)
            for t, row in zip(times, rows):
                m = T[trace_type](header=header(t), trace=np.asarray(row, np.float32).reshape(-1))
                msgs.append((t, c, ser(m, trace_type)))
        if intrinsics is not None:
            c = writer.add_connection("/camera/info", "sensor_msgs/msg/CameraInfo", typestore=ts)
            i = intrinsics
            K = np.array([i.fx, 0, i.cx, 0, i.fy, i.cy, 0, 0, 1.0])
            RoI = T["sensor_msgs/msg/RegionOfInterest"]
            kw = dict(header=header(0.0), height=i.height, width=i.width, distortion_model="plumb_bob",
                      d=np.zeros(5), k=K, r=np.eye(3).reshape(-1),
                      p=np.array([i.fx, 0, i.cx, 0, 0, i.fy, i.cy, 0, 0, 0, 1.0, 0]), binning_x=0, binning_y=0,
                      roi=RoI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
            if ros1:
                kw = {("D" if k == "d" else "K" if k == "k" else "R" if k == "r" else "P" if k == "p" else k): v
                      for k, v in kw.items()}
            msgs.append((0.0, c, ser(T["sensor_msgs/msg/CameraInfo"](**kw), "sensor_msgs/msg/CameraInfo")))
        for t, c, data in sorted(msgs, key=lambda x: x[0]):
            writer.write(c, int(round(max(t, 0.0) * 1e9)) + 1, data)
