"""Traces that arrive while a survey runs: a TCP stream of traces with their poses, and recordings that grow.

The stream format (``docs/CONVENTIONS.md``, "Live trace stream"), little-endian:

- once, the header: the 8 bytes ``GPR3DTR1``, a ``uint32`` length, then that many bytes of UTF-8 JSON with
  ``n_samples`` (int), ``dt_s`` (s) and optionally ``frequency_hz``, ``offset_m`` (transmitter-receiver, m),
  ``eps_r``, ``name``;
- per trace: the 4 bytes ``TRCE``, a ``uint64`` trace index (0, 1, 2, ... in order), a ``float64`` time (s),
  seven ``float64`` of the antenna's pose (``x y z qw qx qy qz``: world metres, the orientation as a unit
  quaternion), then ``n_samples`` ``float32`` samples;
- at the end (optional: a closed connection ends the stream too), the 4 bytes ``END!``.

A stream may also carry what a pose filter needs, declared in the header's ``sensors`` (a list of ``"imu"``,
``"odometry"``, ``"wheel"``, with ``"imu"`` among them): IMU samples (``IMU_``, a ``float64`` time on the IMU
clock, three of specific force in m/s^2 and three of angular rate in rad/s, IMU frame), the visual odometry's
camera poses (``CAMP``, a ``float64`` time on the camera clock, then ``x y z qw qx qy qz`` in the odometry's world)
and survey wheel readings (``WHEL``, a ``float64`` time on the IMU clock and the forward distance, m), each kind in
time order, all interleaved with the traces as they happen. The traces' times are then on the IMU clock, and their
poses may be left out (seven NaN): ``gpr3d live --fuse`` fuses them.

:class:`StreamDecoder` takes bytes as they come and gives whole traces; :func:`encode_header`,
:func:`encode_trace` and ``END`` write the format. :class:`GrowingDZT` and :class:`GrowingTUM` read a DZT
recording and a TUM trajectory that a radar and a pose filter are still writing: each ``poll()`` gives what has
been completed since the last.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError

__all__ = ["END", "HEADER_MAGIC", "SENSORS", "GrowingDT1", "GrowingDZT", "GrowingTUM", "StreamDecoder", "StreamHeader",
           "Trace", "dt1_layout", "encode_camera_pose", "encode_header", "encode_imu", "encode_trace", "encode_wheel"]

HEADER_MAGIC = b"GPR3DTR1"
TRACE_TAG = b"TRCE"
END = b"END!"  #: the end mark
_TRACE = struct.Struct("<4sQd7d")  # tag, index, time, x y z qw qx qy qz
#: the sensor messages a stream may carry: the header's name, its tag and its float64 fields after the tag
SENSORS = {"imu": (b"IMU_", 7), "odometry": (b"CAMP", 8), "wheel": (b"WHEL", 2)}
_SENSOR_OF_TAG = {tag: (name, struct.Struct(f"<4s{n}d")) for name, (tag, n) in SENSORS.items()}
_SENSOR_WORDS = {"imu": "IMU sample", "odometry": "camera pose", "wheel": "wheel reading"}
MAX_HEADER_BYTES = 1 << 20
MAX_SAMPLES = 1 << 20


@dataclass(frozen=True)
class StreamHeader:
    """What every trace of a stream shares."""

    n_samples: int
    dt_s: float
    frequency_hz: float | None = None
    offset_m: float = 0.0
    eps_r: float | None = None
    name: str = "stream"
    sensors: tuple = ()  #: the sensor messages that come beside the traces (names of :data:`SENSORS`)
    imu_rate_hz: float | None = None  #: the IMU's sample rate (else the filter takes its still start's)

    def to_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if v is not None}
        d["sensors"] = list(self.sensors)
        if not self.sensors:
            del d["sensors"]
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "stream") -> "StreamHeader":
        if not isinstance(d, dict):
            raise FormatError(where, "header JSON is not an object")
        try:
            n, dt = d["n_samples"], d["dt_s"]
        except KeyError as exc:
            raise FormatError(where, f"header lacks {exc.args[0]!r}") from None
        if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= MAX_SAMPLES:
            raise FormatError(where, f"header n_samples must be a whole number in 2..{MAX_SAMPLES}, got {n!r}")

        def number(key, value, *, lo=0.0, open_lo=True):
            if value is None:
                return None
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < lo or (open_lo and value == lo):
                raise FormatError(where, f"header {key} must be a finite number {'>' if open_lo else '>='} {lo:g}, "
                                         f"got {value!r}")
            return float(value)

        sensors = d.get("sensors", [])
        if not isinstance(sensors, list) or not all(isinstance(x, str) and x in SENSORS for x in sensors) \
                or len(set(sensors)) != len(sensors):
            raise FormatError(where, f"header sensors must be a list of distinct names out of {', '.join(SENSORS)}, "
                                     f"got {sensors!r}")
        if sensors and "imu" not in sensors:
            raise FormatError(where, f"header sensors {sensors} lack 'imu' (a pose filter propagates with it)")
        return cls(n_samples=n, dt_s=number("dt_s", dt), frequency_hz=number("frequency_hz", d.get("frequency_hz")),
                   offset_m=number("offset_m", d.get("offset_m", 0.0), open_lo=False),
                   eps_r=number("eps_r", d.get("eps_r"), lo=1.0, open_lo=False), name=str(d.get("name", "stream")),
                   sensors=tuple(sensors), imu_rate_hz=number("imu_rate_hz", d.get("imu_rate_hz")))


@dataclass
class Trace:
    """One trace of a stream: its index, time (s), pose ``[x y z qw qx qy qz]`` (NaN: none given) and samples."""

    index: int
    time_s: float
    pose: np.ndarray
    samples: np.ndarray


def encode_header(header: StreamHeader) -> bytes:
    """The stream's opening bytes."""
    body = json.dumps(header.to_dict()).encode()
    return HEADER_MAGIC + struct.pack("<I", len(body)) + body


def encode_trace(index: int, time_s: float, pose, samples) -> bytes:
    """One trace's bytes (``pose``: ``x y z qw qx qy qz``)."""
    p = np.asarray(pose, dtype=np.float64).reshape(7)
    return _TRACE.pack(TRACE_TAG, int(index), float(time_s), *p) + np.asarray(samples, "<f4").tobytes()


def encode_imu(time_s: float, accel, gyro) -> bytes:
    """One IMU sample's bytes: time (s, IMU clock), specific force (m/s^2) and angular rate (rad/s)."""
    return _sensor("imu", time_s, np.r_[np.asarray(accel, float).reshape(3), np.asarray(gyro, float).reshape(3)])


def encode_camera_pose(time_s: float, pose) -> bytes:
    """One odometry frame's bytes: time (s, camera clock) and the camera's pose ``x y z qw qx qy qz``."""
    return _sensor("odometry", time_s, np.asarray(pose, float).reshape(7))


def encode_wheel(time_s: float, distance_m: float) -> bytes:
    """One survey wheel reading's bytes: time (s, IMU clock) and forward distance (m)."""
    return _sensor("wheel", time_s, [float(distance_m)])


def _sensor(name, time_s, values) -> bytes:
    tag, _ = SENSORS[name]
    return _SENSOR_OF_TAG[tag][1].pack(tag, float(time_s), *values)


@dataclass
class StreamDecoder:
    """Bytes in (:meth:`feed`), whole traces out, and the sensor messages by kind (:meth:`take_sensors`);
    :class:`~gpr3d.core.errors.FormatError` names the first thing that breaks the format (a wrong opening, a trace
    out of order, a non-finite sample or pose, a sensor message the header did not declare or out of time
    order)."""

    where: str = "stream"
    header: StreamHeader | None = None
    ended: bool = False
    next_index: int = 0
    _buf: bytearray = field(default_factory=bytearray)
    _sensors: dict = field(default_factory=dict)  # name -> rows not yet taken
    _counts: dict = field(default_factory=dict)  # name -> (messages so far, the last one's time)

    def take_sensors(self) -> dict:
        """The sensor messages decoded since the last call, by kind: ``"imu"`` ``(k, 7)`` rows ``t ax ay az gx gy
        gz``, ``"odometry"`` ``(k, 8)`` ``t x y z qw qx qy qz`` (unit quaternions), ``"wheel"`` ``(k, 2)`` ``t
        distance``; every kind the header declares is there (``k`` may be 0)."""
        out = {}
        for name in (self.header.sensors if self.header is not None else ()):
            rows = self._sensors.pop(name, [])
            out[name] = np.asarray(rows, float).reshape(-1, SENSORS[name][1])
        return out

    def _sensor_message(self, tag) -> bool:
        """Decode the sensor message at the buffer's start; False: not all of it is there yet."""
        name, st = _SENSOR_OF_TAG[tag]
        what = _SENSOR_WORDS[name]
        n, last = self._counts.get(name, (0, -math.inf))
        if name not in self.header.sensors:
            raise FormatError(self.where, f"{what} {n}: a {tag.decode()} message the header's sensors "
                                          f"({list(self.header.sensors)}) do not declare")
        if len(self._buf) < st.size:
            return False
        v = np.asarray(st.unpack_from(self._buf)[1:])
        if not np.all(np.isfinite(v)):
            raise FormatError(self.where, f"{what} {n}: not finite")
        if v[0] <= last:
            raise FormatError(self.where, f"{what} {n}: its time {v[0]:.9g} s is not after the one before "
                                          f"({last:.9g} s)")
        if name == "odometry":
            norm = np.linalg.norm(v[4:])
            if abs(norm - 1.0) > 1e-3:
                raise FormatError(self.where, f"{what} {n}: its orientation is not a unit quaternion (norm {norm:.4g})")
            v[4:] /= norm
        self._sensors.setdefault(name, []).append(v)
        self._counts[name] = (n + 1, v[0])
        del self._buf[:st.size]
        return True

    def feed(self, data: bytes) -> list[Trace]:
        if self.ended and data:
            raise FormatError(self.where, "bytes after the end mark END!")
        self._buf += data
        out: list[Trace] = []
        while True:
            if self.header is None:
                if len(self._buf) < 12:
                    if self._buf and not HEADER_MAGIC.startswith(bytes(self._buf[:8])):
                        raise FormatError(self.where, "does not open with GPR3DTR1: not a gpr3d trace stream")
                    return out
                if bytes(self._buf[:8]) != HEADER_MAGIC:
                    raise FormatError(self.where, "does not open with GPR3DTR1: not a gpr3d trace stream")
                (n,) = struct.unpack("<I", self._buf[8:12])
                if n > MAX_HEADER_BYTES:
                    raise FormatError(self.where, f"header of {n} bytes (at most {MAX_HEADER_BYTES})")
                if len(self._buf) < 12 + n:
                    return out
                try:
                    d = json.loads(bytes(self._buf[12:12 + n]).decode())
                except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                    raise FormatError(self.where, f"header is not JSON ({exc})") from None
                self.header = StreamHeader.from_dict(d, self.where)
                del self._buf[:12 + n]
                continue
            if len(self._buf) < 4:
                return out
            tag = bytes(self._buf[:4])
            if tag == END:
                self.ended = True
                if len(self._buf) > 4:
                    raise FormatError(self.where, "bytes after the end mark END!")
                self._buf.clear()
                return out
            if tag in _SENSOR_OF_TAG:
                if not self._sensor_message(tag):
                    return out
                continue
            if tag != TRACE_TAG:
                raise FormatError(self.where, f"trace {self.next_index}: expected TRCE or END!, got {tag!r}")
            size = _TRACE.size + 4 * self.header.n_samples
            if len(self._buf) < size:
                return out
            _, index, t, *pose = _TRACE.unpack_from(self._buf)
            if index != self.next_index:
                raise FormatError(self.where, f"trace index {index} where {self.next_index} was due (lost or "
                                              "reordered traces)")
            samples = np.frombuffer(bytes(self._buf[_TRACE.size:size]), "<f4").astype(np.float32)
            pose = np.asarray(pose)
            unposed = bool(self.header.sensors) and np.all(np.isnan(pose))  # (poses to be fused)
            if not ((unposed or np.all(np.isfinite(pose))) and math.isfinite(t)):
                raise FormatError(self.where, f"trace {index}: its pose or time is not finite")
            if not unposed and abs(np.linalg.norm(pose[3:]) - 1.0) > 1e-3:
                raise FormatError(self.where, f"trace {index}: its orientation is not a unit quaternion "
                                              f"(norm {np.linalg.norm(pose[3:]):.4g})")
            if not np.all(np.isfinite(samples)):
                raise FormatError(self.where, f"trace {index}: non-finite samples")
            out.append(Trace(int(index), float(t), pose, samples))
            self.next_index += 1
            del self._buf[:size]

    def close(self) -> None:
        """The connection closed: a trace cut short is an error; otherwise the stream has ended."""
        if self._buf:
            raise FormatError(self.where, f"ends inside a trace or header ({len(self._buf)} bytes left over)")
        self.ended = True


class GrowingDZT:
    """A GSSI DZT file that a radar is still writing (channel ``channel``): :meth:`poll` gives the traces
    completed since the last call, as :func:`gpr3d.io.dzt.read_dzt` reads them (binary zero taken off, the
    first two samples, a counter and a mark word, replaced by the third). Until the header is there,
    ``header`` is None and polls give nothing."""

    def __init__(self, path, channel: int = 0):
        self.path = Path(path)
        self.channel = int(channel)
        self.header: dict | None = None
        self.n_read = 0

    def _open_header(self) -> bool:
        from gpr3d.io.dzt import HEADER_BYTES, read_dzt_header

        try:
            size = self.path.stat().st_size
        except FileNotFoundError:
            return False
        if size < HEADER_BYTES:
            return False
        try:
            hdr = read_dzt_header(self.path)
        except FormatError as exc:
            if "beyond the end" in str(exc) or "shorter than" in str(exc):
                return False  # the headers are still being written
            raise
        if not 0 <= self.channel < hdr["n_channels"]:
            raise FormatError(self.path, f"has {hdr['n_channels']} channel(s): no channel {self.channel}")
        self.header = hdr
        return True

    @property
    def dt_s(self) -> float:
        return self.header["range_ns"] * 1e-9 / self.header["n_samples"]

    def poll(self) -> np.ndarray:
        """``(k, n_samples)`` float32: the whole traces written since the last poll (k may be 0)."""
        if self.header is None and not self._open_header():
            return np.zeros((0, 0), np.float32)
        h = self.header
        ns, nch, bits = h["n_samples"], h["n_channels"], h["bits"]
        tb = ns * nch * bits // 8
        size = self.path.stat().st_size
        have = (size - h["data_offset"]) // tb
        if have < self.n_read:
            raise FormatError(self.path, f"shrank while being read ({have} whole traces, {self.n_read} read)")
        k = int(have - self.n_read)
        if k == 0:
            return np.zeros((0, ns), np.float32)
        dtype = {8: "<u1", 16: "<u2", 32: "<i4"}[bits]
        zero = {8: 128.0, 16: 32768.0, 32: 0.0}[bits]
        with open(self.path, "rb") as fh:
            fh.seek(h["data_offset"] + self.n_read * tb)
            raw = np.fromfile(fh, dtype=dtype, count=k * ns * nch)
        if raw.size != k * ns * nch:
            raise FormatError(self.path, "shrank while being read")
        out = raw.reshape(k, nch, ns)[:, self.channel, :].astype(np.float32) - np.float32(zero)
        if ns > 2:
            out[:, :2] = out[:, 2:3]
        self.n_read += k
        return out


def dt1_layout(path) -> tuple[int, int] | None:
    """``(points per trace, bytes per point)`` of a pulseEKKO DT1 file from its first trace header (bytes per point
    as :func:`gpr3d.io.dt1.read_dt1` takes them); None while the file or that header is not all there yet; a
    one-line :class:`~gpr3d.core.errors.FormatError` where the header cannot be a DT1's."""
    from gpr3d.io.dt1 import TRACE_HEADER_BYTES

    try:
        with open(path, "rb") as fh:
            head = fh.read(TRACE_HEADER_BYTES)
    except FileNotFoundError:
        return None
    if len(head) < TRACE_HEADER_BYTES:
        return None
    first = np.frombuffer(head, dtype="<f4")
    npts = float(first[2])
    if not (math.isfinite(npts) and npts == int(npts) and 2 <= npts <= 10**6):
        raise FormatError(Path(path), f"first trace header says {npts:g} points a trace: not a pulseEKKO DT1, or "
                                      "corrupt")
    bpp = int(first[5]) if math.isfinite(first[5]) and int(first[5]) in (2, 4) else 2
    return int(npts), bpp


class GrowingDT1:
    """A pulseEKKO DT1 file that a radar is still writing: :meth:`poll` gives the traces completed since the last
    call, as :func:`gpr3d.io.dt1.read_dt1` reads them (16- or 32-bit samples as float32).

    The points per trace and bytes per point come from the first trace's own header; the sample interval from the
    HD header beside the file (``TOTAL TIME WINDOW / NUMBER OF PTS/TRC``, which must agree with the trace header)
    where it is there, else from ``dt_s``; ``frequency_hz`` and ``separation_m`` from the HD (None without one).
    Until the first trace header is there, ``header`` is None and polls give nothing."""

    def __init__(self, path, dt_s: float | None = None):
        self.path = Path(path)
        self.given_dt_s = dt_s
        self.header: dict | None = None
        self.n_read = 0

    def open_header(self) -> bool:
        """Read the first trace header (and the HD beside the file): False while it is not all there yet."""
        from gpr3d.io._common import sidecar
        from gpr3d.io.dt1 import _UNITS_M, _hd_number, read_hd

        layout = dt1_layout(self.path)
        if layout is None:
            return False
        npts, bpp = layout
        dt_s, freq, sep = self.given_dt_s, None, None
        hd_path = sidecar(self.path, ".hd")
        if hd_path is not None:
            hd = read_hd(hd_path)
            hd_pts = _hd_number(hd_path, hd, "NUMBER OF PTS/TRC")
            window_ns = _hd_number(hd_path, hd, "TOTAL TIME WINDOW")
            if hd_pts != npts:
                raise FormatError(self.path, f"first trace header says {npts} points, {hd_path.name} says "
                                             f"{hd_pts:g}: mismatched files")
            if not (math.isfinite(window_ns) and window_ns > 0):
                raise FormatError(hd_path, f"TOTAL TIME WINDOW must be a positive number of ns, got {window_ns:g}")
            dt_s = window_ns * 1e-9 / npts
            if self.given_dt_s is not None and not math.isclose(self.given_dt_s, dt_s, rel_tol=1e-6):
                raise FormatError(self.path, f"--dt {self.given_dt_s * 1e9:g} ns disagrees with {hd_path.name}'s "
                                             f"{dt_s * 1e9:g} ns (TOTAL TIME WINDOW / NUMBER OF PTS/TRC): drop --dt")
            mhz = _hd_number(hd_path, hd, "NOMINAL FREQUENCY", required=False)
            freq = mhz * 1e6 if mhz else None
            unit_name = hd.get("POSITION UNITS", "m").strip().lower()
            if unit_name not in _UNITS_M:  # (as read_dt1: the separation is in these units)
                raise FormatError(hd_path, f"unknown POSITION UNITS {unit_name!r}")
            unit = _UNITS_M[unit_name]
            sep = _hd_number(hd_path, hd, "ANTENNA SEPARATION", required=False)
            sep = None if sep is None else sep * unit
        if dt_s is None:
            raise FormatError(self.path, "no HD header beside it to give the sample interval: give it (--dt, in ns)")
        self.header = {"n_samples": npts, "bytes_per_point": bpp, "dt_s": float(dt_s), "frequency_hz": freq,
                       "separation_m": sep, "hd": None if hd_path is None else str(hd_path)}
        return True

    @property
    def dt_s(self) -> float:
        return self.header["dt_s"]

    def poll(self) -> np.ndarray:
        """``(k, n_samples)`` float32: the whole traces written since the last poll (k may be 0)."""
        from gpr3d.io.dt1 import TRACE_HEADER_BYTES

        if self.header is None and not self.open_header():
            return np.zeros((0, 0), np.float32)
        ns, bpp = self.header["n_samples"], self.header["bytes_per_point"]
        tb = TRACE_HEADER_BYTES + ns * bpp
        have = self.path.stat().st_size // tb
        if have < self.n_read:
            raise FormatError(self.path, f"shrank while being read ({have} whole traces, {self.n_read} read)")
        k = int(have - self.n_read)
        if k == 0:
            return np.zeros((0, ns), np.float32)
        rec = np.dtype([("h", "<f4", (TRACE_HEADER_BYTES // 4,)), ("d", "<i2" if bpp == 2 else "<i4", (ns,))])
        with open(self.path, "rb") as fh:
            fh.seek(self.n_read * tb)
            arr = np.fromfile(fh, dtype=rec, count=k)
        if len(arr) != k:
            raise FormatError(self.path, "shrank while being read")
        bad = np.nonzero(arr["h"][:, 2] != ns)[0]
        if bad.size:
            i = int(bad[0])
            raise FormatError(self.path, f"trace {self.n_read + i} header says {arr['h'][i, 2]:g} points, the first "
                                         f"says {ns}: corrupt")
        self.n_read += k
        return arr["d"].astype(np.float32)


class GrowingTUM:
    """A TUM trajectory (``t tx ty tz qx qy qz qw`` per line) still being written: :meth:`poll` gives the rows of
    the lines completed (ended by a newline) since the last call, as ``(k, 8)`` ``[t x y z qw qx qy qz]``."""

    def __init__(self, path):
        self.path = Path(path)
        self._offset = 0
        self.n_read = 0
        self._last_t = -math.inf

    def poll(self) -> np.ndarray:
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self._offset)
                chunk = fh.read()
        except FileNotFoundError:
            return np.zeros((0, 8))
        end = chunk.rfind(b"\n")
        if end < 0:
            return np.zeros((0, 8))
        self._offset += end + 1
        rows = []
        for line in chunk[:end].decode("utf-8", errors="replace").splitlines():
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            parts = s.split()
            try:
                v = [float(x) for x in parts]
            except ValueError:
                raise FormatError(self.path, f"pose {self.n_read + len(rows)}: not numbers: {s[:60]!r}") from None
            if len(v) != 8 or not all(map(math.isfinite, v)):
                raise FormatError(self.path, f"pose {self.n_read + len(rows)}: expected 8 finite numbers "
                                             f"(t tx ty tz qx qy qz qw), got {s[:60]!r}")
            q = np.array([v[7], v[4], v[5], v[6]])
            if np.linalg.norm(q) < 1e-9:
                raise FormatError(self.path, f"pose {self.n_read + len(rows)}: a zero quaternion")
            if v[0] < self._last_t:
                raise FormatError(self.path, f"timestamps run backwards at pose {self.n_read + len(rows)}")
            self._last_t = v[0]
            rows.append([v[0], v[1], v[2], v[3], *(q / np.linalg.norm(q))])
        self.n_read += len(rows)
        return np.asarray(rows, dtype=float).reshape(-1, 8)
