"""Live mode: traces migrated as they arrive, targets refreshed while the survey runs (``gpr3d live``).

A source gives traces with their poses as a radar writes them (:class:`TCPSource`: the trace stream of
:mod:`gpr3d.io.stream`; :class:`FileSource`: a DZT recording and a TUM trajectory that grow; :class:`BagSource`:
a ROS bag replayed at its own pace), read by a thread
of its own (:class:`SourceReader`) that stamps each trace with the time it came. :class:`LiveReconstruction`
takes them in batches:

1. **time zero** is fixed once, from the first ``time_zero_traces`` traces (the direct-wave peak of their mean
   trace, as ``reconstruct`` estimates it), and every trace is cut there;
2. **background**: the mean over a moving window of ``background_window`` traces is taken off: by default the
   window ends at the trace (``background_trailing``: no delay); centred, a trace is final once half a window has
   followed it;
3. **migration**: each final trace is added once into the voxels its aperture reaches (in batches of at least
   ``min_batch`` traces, or whatever waits when a refresh is due), on a lattice of tiles
   (``tile_voxels`` a side, voxel centres on whole multiples of the spacing); the image and the fold are summed
   per tile; tiles no recent trace can reach are written to ``OUT/tiles/`` and dropped from memory (read back if
   the cart returns), so memory follows the cart, not the survey;
4. **detection** runs on each window of raw traces as it fills (the shipped detector, ``--no-detect`` off), in a
   thread of its own beside steps 3 and 5 (``detect_thread``; the windows' detections are kept in their order,
   as when they run in turn);
5. every ``refresh_s`` (from the start of the last refresh) the targets of the tiles in memory are extracted and
   ``OUT/live.json`` (traces, rate, lag, targets, detections) is rewritten atomically; without the detector's
   thread, a due refresh comes before the next detector window.

At the end (the stream's end mark, ``until_idle_s`` without a new trace, or Ctrl-C) the volume over every antenna
position is put together from the tiles and finished exactly as ``gpr3d reconstruct`` finishes its own (fold
normalisation, envelope, targets): with the settings written to ``config.json`` (``time_zero_s``,
``background_window``, ``background_trailing``, ``lattice``, ``signal_depth`` off: the whole record's depth, or
``max_depth_m``) a batch ``reconstruct`` of the same traces gives the
same volume, to float rounding. A survey whose volume would exceed ``final_volume_voxels`` keeps its tiles in
``OUT/tiles`` and the last refresh's targets in ``OUT/live.json`` instead.
"""

from __future__ import annotations

import json
import math
import socket
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.rows import GrowingRows
from gpr3d.core.units import velocity_from_eps_r
from gpr3d.io.stream import GrowingDT1, GrowingDZT, GrowingTUM, StreamDecoder, StreamHeader

__all__ = ["BagSource", "FileSource", "LiveConfig", "LiveReconstruction", "LiveSummary", "SourceReader", "TCPSource",
           "open_source", "run_live"]


@dataclass
class LiveConfig:
    """Live mode's settings beside the migration's (:class:`~gpr3d.migration.config.ReconstructConfig`)."""

    #: the migration's settings (``eps_r`` None: the stream header's); live mode needs an aperture (it bounds
    #: what each trace reaches) and sets ``time_zero_s``, ``background_window``, ``background_trailing`` and
    #: ``lattice`` itself
    reconstruct: object = None
    background_window: int = 256  #: traces in the moving background window
    #: the window ends at each trace (no waiting); False: centred on it (a trace waits for half a window)
    background_trailing: bool = True
    time_zero_traces: int = 64  #: traces time zero is estimated from
    tile_voxels: int = 32  #: a tile's side in voxels
    #: how often the targets and ``live.json`` are refreshed (s; longer where a refresh would take more than a third
    #: of the time). A trace waits about this long plus a refresh for its targets: 0.4 s (instead of 0.5) took the
    #: worst latency of a 208,000-trace replay at 800/s on 2 Intel cores from 0.93-1.19 s to 0.89 s, for 13 % more
    #: time refreshing (benchmarks/bench_live.py)
    refresh_s: float = 0.4
    preview_angle_step_deg: float = 1.0  #: the refreshes' Hough angle step (the final targets: the batch one's)
    #: the most Hough peaks a refresh examines per group of columns (the final targets: the batch's 400); 100 gave
    #: the same targets at every refresh of the benchmark's survey in 43 % less time
    preview_max_peaks: int = 100
    detect: bool = True  #: run the detector on each window of traces as it fills
    #: run the detector's windows in a thread of its own, beside the migration and the refreshes (False: in turn
    #: with them, in the main loop)
    detect_thread: bool = True
    score: float = 0.5  #: the detector's score threshold
    until_idle_s: float | None = 5.0  #: end once no trace has come for this long (None: only at the end mark)
    start_timeout_s: float | None = 60.0  #: give up when no trace at all has come for this long (None: wait)
    #: the most traces migrated in one go: a backlog is worked off in such batches, a refresh between them when due
    max_batch: int = 256
    #: the most raw traces the detector may fall behind by before it takes windows without overlap (twice as many:
    #: it skips ahead); they wait in memory
    detect_backlog: int = 4096
    #: traces gathered before a migration (each costs a grid over the batch's reach: 16-trace batches measured
    #: 1.1 ms a trace, 100-trace ones 0.44 ms); a due refresh migrates whatever is waiting first
    min_batch: int = 128
    final_volume_voxels: int = 30_000_000  #: put the final volume together only up to this size (else: its tiles)
    #: keep the memory the loop frees for its next batch or refresh (glibc's ``mallopt``; elsewhere nothing): fresh
    #: pages from the system measured up to 0.24 s per 64 MB on a virtual machine, against 4 ms as a rule
    keep_memory: bool = True


@dataclass
class LiveSummary:
    """What a live run did (also ``OUT/live.json``)."""

    n_traces: int
    wall_s: float
    traces_per_s: float
    lag_s: float  #: at the end: how long after the newest trace arrived the last was migrated
    latency_s: dict  #: trace arrival -> refreshed targets: median, 99th percentile and max over the refreshes
    peak_tiles: int  #: the most tiles held in memory at once
    n_targets: int
    n_detections: int
    files: list = field(default_factory=list)
    final_volume: bool = True
    #: the detector behind: windows it took without overlap, and traces no window saw (``LiveConfig.detect_backlog``)
    detect_thinned: int = 0
    detect_skipped: int = 0
    #: the seconds spent on each kind of work: ``migrate`` (each trace into its tiles, the last ones at the end
    #: included), ``detect`` (the detector's windows), ``refresh`` (targets and ``live.json`` while running; not the
    #: final volume's extraction): where the time went when live mode falls behind. The detector's thread
    #: (``LiveConfig.detect_thread``) runs beside the other two: then ``detect`` overlaps them
    busy_s: dict = field(default_factory=dict)

    def line(self) -> str:
        return f"{self.n_traces} traces, {self.traces_per_s:.0f} traces/s, lag {self.lag_s:.2f} s"


# -- sources -------------------------------------------------------------------------------------------------------

class TCPSource:
    """Traces with poses from a TCP server speaking the :mod:`gpr3d.io.stream` format (a radar's bridge, or
    ``gpr3d replay --to tcp://...``). Connects on the first poll, trying again until ``connect_s`` have passed.

    ``fuse`` (a dict: ``rig``, ``still_s``; either may be left out) fuses the antenna's poses from the stream's
    sensor messages (its IMU samples, and the camera poses and wheel readings its header declares) as they come
    (:class:`~gpr3d.pose.eskf.ForwardFusion`, no smoothing): a trace is given once the filter has passed its time;
    traces outside the IMU's span are left out and counted (``skipped``). Without it the sensor messages are
    read and let go, and every trace must carry its pose. A fused trace's arrival (what its latency counts from) is
    when it came from the socket, not when the filter let it go (the fourth array :meth:`poll` gives)."""

    def __init__(self, host: str, port: int, *, connect_s: float = 10.0, fuse: dict | None = None,
                 clock=time.monotonic):
        self.host, self.port = host, int(port)
        self.connect_s = connect_s
        self.where = f"tcp://{host}:{port}"
        self.decoder = StreamDecoder(where=self.where)
        self.sock = None
        self._t_start = None
        if fuse is not None and fuse.get("rig") is not None and not isinstance(fuse["rig"], dict):
            from gpr3d.io.inertial import read_rig

            fuse = {**fuse, "rig": read_rig(fuse["rig"])}  # (read now: a wrong file is named before any work)
        self.fuse = fuse
        self.fused = None  #: the pose filter once the header has come (with ``fuse``)
        self._held = []  # (trace, when it came) waiting for the filter to pass their times
        self.skipped = 0  #: traces outside the IMU's span (with ``fuse``)
        self.clock = clock

    @property
    def header(self) -> StreamHeader | None:
        return self.decoder.header

    @property
    def ended(self) -> bool:
        return self.decoder.ended and not self._held

    def _connect(self) -> bool:
        if self._t_start is None:
            self._t_start = time.monotonic()
        try:
            s = socket.create_connection((self.host, self.port), timeout=1.0)
        except OSError as exc:
            if time.monotonic() - self._t_start > self.connect_s:
                raise GPR3DError(f"{self.where}: no connection after {self.connect_s:g} s "
                                 f"({exc.strerror or exc})") from None
            return False
        s.setblocking(False)
        self.sock = s
        return True

    def poll(self):
        """``(data (k, n_samples) float32, poses (k, 7), times (k,))`` of the traces received since the last poll."""
        if self.sock is None and not self._connect():
            return None
        chunks = []
        closed = False
        while True:
            try:
                b = self.sock.recv(1 << 20)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionError:
                closed = True
                break
            if not b:
                closed = True
                break
            chunks.append(b)
            if sum(map(len, chunks)) > (64 << 20):
                break
        traces = self.decoder.feed(b"".join(chunks))
        if closed and not self.decoder.ended:
            self.decoder.close()
        header = self.decoder.header
        if header is None:
            return None
        sensors = self.decoder.take_sensors()  # (taken either way: nothing piles up)
        if self.fuse is None:
            for t in traces:
                if np.isnan(t.pose[0]):
                    raise GPR3DError(f"{self.where}: trace {t.index} carries no pose (the stream's poses are to be "
                                     "fused from its sensors): give --fuse (and --rig)")
            return _stack(traces, header)
        return self._fused(traces, sensors, header)

    def _fused(self, traces, sensors, header):
        if self.fused is None:
            if "imu" not in header.sensors:
                raise GPR3DError(f"{self.where}: --fuse needs IMU samples in the stream; its header declares none "
                                 "(sensors)")
            self.fused = _StreamFusion(header, where=self.where, **self.fuse)
        f = self.fused
        if traces:
            t = np.array([tr.time_s for tr in traces])
            last = self._held[-1][0].time_s if self._held else -math.inf
            if np.any(np.diff(np.r_[last, t]) < 0):
                raise GPR3DError(f"{self.where}: trace {traces[int(np.argmax(np.diff(np.r_[last, t]) < 0))].index}: "
                                 "its time runs backwards (fused poses need the traces in time order)")
            came = self.clock()
            self._held += [(tr, came) for tr in traces]
        f.add(sensors, ended=self.decoder.ended)
        give = []
        until = f.until
        while self._held and (self._held[0][0].time_s <= until or self.decoder.ended):
            tr, came = self._held.pop(0)
            if f.first_s <= tr.time_s <= until:
                give.append((tr, came))
            else:
                self.skipped += 1
        if not give:
            return np.zeros((0, header.n_samples), np.float32), np.zeros((0, 7)), np.zeros(0), np.zeros(0)
        times = np.array([tr.time_s for tr, _ in give])
        return (np.stack([tr.samples for tr, _ in give]), f.at(times), times,
                np.array([came for _, came in give]))

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()


class FileSource:
    """A DZT or pulseEKKO DT1 recording and a TUM trajectory (one pose per trace, in trace order) that are still
    being written: trace ``i`` is given once pose ``i`` is there. The stream never ends by itself
    (``until_idle_s`` ends it). A DT1's sample interval comes from its HD header, or ``dt_s`` where there is none
    yet; its antenna separation from the HD where ``offset_m`` is None."""

    def __init__(self, recording, poses, *, channel: int = 0, offset_m: float | None = None,
                 frequency_hz: float | None = None, dt_s: float | None = None):
        kind = Path(recording).suffix.lower()
        if kind not in (".dzt", ".dt1"):
            raise GPR3DError(f"{recording}: live mode reads growing DZT or DT1 files (or tcp://HOST:PORT)")
        if poses is None:
            raise GPR3DError("live mode needs the antenna's poses: give --poses (a TUM file, one pose per trace, "
                             "that may grow with the recording)")
        if kind == ".dt1" and channel != 0:
            raise GPR3DError(f"{recording}: a DT1 file holds one channel (--channel is for a DZT)")
        if kind == ".dzt" and dt_s is not None:
            raise GPR3DError(f"{recording}: a DZT header gives the sample interval (--dt is for a DT1 without its "
                             "HD, or a ROS bag)")
        self.recording = GrowingDZT(recording, channel) if kind == ".dzt" else GrowingDT1(recording, dt_s)
        self.channel = int(channel)
        self.tum = GrowingTUM(poses)
        self.offset_m = offset_m
        self.frequency_hz = frequency_hz
        self._data = np.zeros((0, 0), np.float32)
        self._poses = np.zeros((0, 8))
        self.header = None
        self.ended = False
        self.waiting_for_poses = 0  #: traces read whose poses have not come yet

    @property
    def path(self) -> Path:
        return self.recording.path

    def _header(self) -> StreamHeader:
        h = self.recording.header
        if isinstance(self.recording, GrowingDT1):
            offset = self.offset_m if self.offset_m is not None else (h["separation_m"] or 0.0)
            return StreamHeader(n_samples=h["n_samples"], dt_s=h["dt_s"],
                                frequency_hz=self.frequency_hz or h["frequency_hz"], offset_m=offset,
                                name=str(self.path))
        from gpr3d.io.dzt import _antenna_mhz

        mhz = _antenna_mhz(h["antennas"][self.channel])
        return StreamHeader(n_samples=h["n_samples"], dt_s=self.recording.dt_s,
                            frequency_hz=self.frequency_hz or (mhz * 1e6 if mhz else None),
                            offset_m=self.offset_m or 0.0, eps_r=h["eps_r"], name=str(self.path))

    def poll(self):
        d = self.recording.poll()
        if self.recording.header is None:
            return None
        if self.header is None:
            self.header = self._header()
            self._data = np.zeros((0, self.header.n_samples), np.float32)
        p = self.tum.poll()
        self._data = np.concatenate([self._data, d]) if len(d) else self._data
        self._poses = np.concatenate([self._poses, p]) if len(p) else self._poses
        k = min(len(self._data), len(self._poses))
        self.waiting_for_poses = len(self._data) - k
        data, poses = self._data[:k], self._poses[:k]
        self._data, self._poses = self._data[k:], self._poses[k:]
        return data, poses[:, 1:], poses[:, 0]

    def close(self) -> None:
        pass


class _FusedPoses:
    """The antenna's poses fused from a bag's IMU and odometry topics as the replay comes to them
    (:class:`~gpr3d.pose.eskf.ForwardFusion`: the IMU propagates, the odometry's camera poses, taken frame to
    frame, correct; no smoothing): :meth:`feed_to` gives the filter what is stamped up to a bag time, and poses are
    given where the filter has passed (:attr:`until`). With the same settings ``gpr3d pose fuse --bag`` (no
    ``--smooth``) gives the same poses."""

    def __init__(self, bag, *, imu_topic=None, odometry_topic=None, rig=None, still_s: float = 1.0):
        from gpr3d.io.inertial import read_rig, relative_from_camera_poses
        from gpr3d.io.rosbag import read_bag_imu, read_bag_trajectory
        from gpr3d.pose.eskf import EskfConfig, ForwardFusion

        self.imu = read_bag_imu(bag, imu_topic)
        self.vo = relative_from_camera_poses(read_bag_trajectory(bag, odometry_topic))
        self.cfg = EskfConfig(init_still_s=still_s, **(read_rig(rig) if rig else {}))
        self.ff = ForwardFusion(self.cfg, rate_hz=self.imu.rate_hz)
        self.first_s, self.last_s = float(self.imu.t_s[0]), float(self.imu.t_s[-1])  #: the poses' span
        self.ni = self.nv = 0
        self.done = False

    @property
    def until(self) -> float:
        """The bag time up to which the poses are final."""
        n = self.ff.n_done
        return float(self.imu.t_s[n - 1]) if n >= 2 else -math.inf

    def feed_to(self, t: float) -> None:
        if self.done:
            return
        imu, vo, ff = self.imu, self.vo, self.ff
        ni = int(np.searchsorted(imu.t_s, t, side="right"))
        nv = int(np.searchsorted(vo.t_s, t, side="right"))
        if ni > self.ni:
            ff.add_imu(imu.t_s[self.ni:ni], imu.accel[self.ni:ni], imu.gyro[self.ni:ni])
        if nv > self.nv:
            a = self.nv
            ff.add_frames(vo.t_s[a:nv], vo.R[a:nv], vo.p[a:nv], vo.cov[a:nv], vo.valid[a:nv], vo.ref[a:nv])
        self.ni, self.nv = ni, nv
        if ni == imu.t_s.size and nv == vo.t_s.size:
            ff.finish()  # (everything came: the filter runs to the last sample)
            self.done = True
        else:
            ff.run()

    def at(self, times) -> np.ndarray:
        at = self.ff.antenna_at(times)
        return np.c_[at.positions_xyz, at.orientations_quat_wxyz]


class _StreamFusion:
    """The antenna's poses fused from a trace stream's sensor messages as they come (:class:`TCPSource` with
    ``fuse``): IMU samples, the odometry's camera poses taken frame to frame
    (:class:`~gpr3d.io.inertial.CameraMotions`) and wheel readings, as the header declares them, fed to
    :class:`~gpr3d.pose.eskf.ForwardFusion`. The IMU's rate is the header's ``imu_rate_hz``, else the median
    interval of the samples of the still start (which the filter waits for anyway)."""

    def __init__(self, header: StreamHeader, *, where: str = "stream", rig=None, still_s: float = 1.0):
        from gpr3d.io.inertial import CameraMotions, read_rig
        from gpr3d.pose.eskf import EskfConfig

        self.where = where
        rig = rig if isinstance(rig, dict) else (read_rig(rig) if rig else {})  # (a path, or what it holds)
        self.cfg = EskfConfig(init_still_s=still_s, **rig)
        self.rate_hz = header.imu_rate_hz
        self.sensors = header.sensors
        self.motions = CameraMotions()
        self.ff = None
        self._early = {name: [] for name in self.sensors}  # what came before the filter could be made
        self.first_s = math.inf  #: the first IMU sample's time (traces before it have no pose)

    def _make(self, ended: bool) -> bool:
        from gpr3d.pose.eskf import ForwardFusion

        imu = np.concatenate(self._early["imu"]) if self._early["imu"] else np.zeros((0, 7))
        if ended and len(imu) < 2:
            raise GPR3DError(f"{self.where}: the stream ended after {len(imu)} IMU sample(s): too few to fuse poses")
        if self.rate_hz is None:
            if len(imu) < 2 or (imu[-1, 0] - imu[0, 0] < self.cfg.init_still_s and not ended):
                return False
            self.rate_hz = float(1.0 / np.median(np.diff(imu[:, 0])))
        self.ff = ForwardFusion(self.cfg, rate_hz=self.rate_hz, wheel="wheel" in self.sensors)
        if "odometry" not in self.sensors:
            self.ff.end_frames()
        early, self._early = self._early, None
        self._feed({name: np.concatenate(rows) if rows else np.zeros((0, 1)) for name, rows in early.items()})
        return True

    def _feed(self, sensors: dict) -> None:
        ff = self.ff
        imu, cam, wheel = sensors.get("imu"), sensors.get("odometry"), sensors.get("wheel")
        if imu is not None and len(imu):
            self.first_s = min(self.first_s, float(imu[0, 0]))
            ff.add_imu(imu[:, 0], imu[:, 1:4], imu[:, 4:7])
        if cam is not None and len(cam):
            t, R, p, cov, valid = self.motions.add(cam[:, 0], cam[:, 1:4], cam[:, 4:8])
            ff.add_frames(t, R, p, cov, valid)
        if wheel is not None and len(wheel):
            ff.add_wheel(wheel[:, 0], wheel[:, 1])

    def add(self, sensors: dict, *, ended: bool = False) -> None:
        """Take the sensor messages that came (:meth:`gpr3d.io.stream.StreamDecoder.take_sensors`) and move the
        filter on; ``ended``: none will follow (the filter runs to the last IMU sample)."""
        try:
            if self.ff is None:
                for name, rows in sensors.items():
                    if len(rows):
                        self._early[name].append(rows)
                if not self._make(ended):
                    return
            else:
                self._feed(sensors)
            if ended:
                self.ff.finish()
            else:
                self.ff.run()
        except InvalidDataError as exc:
            raise GPR3DError(f"{self.where}: {exc}") from None

    @property
    def until(self) -> float:
        """The time up to which the poses are final."""
        n = self.ff.n_done if self.ff is not None else 0
        return float(self.ff.imu_t[n - 1]) if n >= 2 else -math.inf

    def at(self, times) -> np.ndarray:
        at = self.ff.antenna_at(times)
        return np.c_[at.positions_xyz, at.orientations_quat_wxyz]


class BagSource:
    """A ROS 1 or ROS 2 bag replayed at its own pace (``speed`` times it; None: as fast as it reads): the traces of
    a GPR trace topic (:func:`gpr3d.io.rosbag.iter_bag_traces`), each with the antenna's pose interpolated at its
    stamp from a pose topic of the same bag (PoseStamped, PoseWithCovarianceStamped, Odometry) or a TUM file.
    A trace is given once the replay clock has passed its stamp and the first pose after it (as a radar and a pose
    filter deliver them live); traces outside the poses' time span are left out and counted (``skipped``). The
    bag's trace messages carry no sample interval: ``dt_s`` is required.

    ``fuse`` (a dict: ``imu_topic``, ``odometry_topic``, ``rig``, ``still_s``; any may be left out) fuses the
    poses from the bag's IMU and odometry as the replay comes to them instead
    (:class:`~gpr3d.pose.eskf.ForwardFusion`): a trace is then given once the filter has passed its stamp."""

    def __init__(self, bag, *, dt_s: float, trace_topic: str | None = None, pose_topic: str | None = None,
                 poses=None, samples_per_trace: int | None = None, speed: float | None = 1.0,
                 offset_m: float = 0.0, frequency_hz: float | None = None, eps_r: float | None = None,
                 clock=time.monotonic, fuse: dict | None = None):
        from gpr3d.io.rosbag import iter_bag_traces, read_bag_trajectory

        if not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and 0 < dt_s < 1e-6):
            raise GPR3DError(f"{bag}: a bag's traces carry no sample interval: give it (--dt, in ns; got {dt_s!r} s)")
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise GPR3DError(f"the replay speed must be a positive number, got {speed!r}")
        if poses is not None and pose_topic is not None:
            raise GPR3DError(f"{bag}: poses from a TUM file (--poses) or from the bag's {pose_topic}: give one")
        if fuse is not None and (poses is not None or pose_topic is not None):
            raise GPR3DError(f"{bag}: poses fused from the IMU and odometry (--fuse) or given "
                             f"({'--poses' if poses is not None else '--pose-topic'}): give one")
        self._traces = iter_bag_traces(bag, trace_topic, samples_per_trace=samples_per_trace)  # (checked now)
        self.fused = self.trajectory = None
        if fuse is not None:
            self.fused = _FusedPoses(bag, **fuse)
        elif poses is not None:
            from gpr3d.io.trajectory import read_tum

            self.trajectory = read_tum(poses)
        else:
            self.trajectory = read_bag_trajectory(bag, pose_topic)
        if self.trajectory is not None:
            ts = self.trajectory.timestamps_s
            if ts.size < 2 or np.any(np.diff(ts) <= 0):
                raise GPR3DError(f"{poses or bag}: the poses' stamps must increase strictly (two poses at least)")
        self.path = str(bag)
        self.dt_s, self.speed, self.clock = float(dt_s), speed, clock
        self.offset_m, self.frequency_hz, self.eps_r = offset_m, frequency_hz, eps_r
        self._next = None  # the next message, read but not yet due
        self._start = None  # (bag time, clock) when the replay began
        self.header = None
        self.ended = False
        self.skipped = 0  #: traces outside the poses' time span

    def _span(self) -> tuple:
        if self.fused is not None:
            return self.fused.first_s, self.fused.last_s
        return float(self.trajectory.timestamps_s[0]), float(self.trajectory.timestamps_s[-1])

    def _due(self, t: float) -> float:
        """The bag time at which a trace stamped ``t`` can be given: once the first pose after it has come (fused
        poses: once the replay has passed it, and the filter too)."""
        if self.fused is not None:
            return t
        ts = self.trajectory.timestamps_s
        return max(t, float(ts[min(int(np.searchsorted(ts, t)), ts.size - 1)]))

    def poll(self):
        now = self.clock()
        times, rows = [], []
        while not self.ended:
            if self._next is None:
                try:
                    self._next = next(self._traces)
                except StopIteration:
                    self.ended = True
                    break
            t, tr = self._next
            if self._start is None:
                self._start = (self._due(t), now)
            if self.speed is not None and (self._due(t) - self._start[0]) / self.speed > now - self._start[1]:
                break  # not yet
            first, last = self._span()
            if self.fused is not None and first <= t <= last:
                if self.fused.until < t:  # the filter first takes in what the replay has passed
                    self.fused.feed_to(math.inf if self.speed is None else
                                       self._start[0] + (now - self._start[1]) * self.speed)
                if self.fused.until < t:
                    break  # the filter has not passed it yet
            self._next = None
            if self.header is None:
                self.header = StreamHeader(n_samples=tr.shape[1], dt_s=self.dt_s, frequency_hz=self.frequency_hz,
                                           offset_m=self.offset_m, eps_r=self.eps_r, name=self.path)
            if not first <= t <= last:
                self.skipped += len(tr)
                continue
            times.extend([t] * len(tr))
            rows.append(tr)
        if self.header is None:
            return None
        if not rows:
            return np.zeros((0, self.header.n_samples), np.float32), np.zeros((0, 7)), np.zeros(0)
        data = np.concatenate(rows)  # (one width: iter_bag_traces holds every message to the first's)
        if self.fused is not None:  # (a trace came when the replay passed its stamp, not when the filter did)
            came = (np.full(len(times), now) if self.speed is None else
                    np.minimum(now, self._start[1] + (np.asarray(times) - self._start[0]) / self.speed))
            return data, self.fused.at(times), np.asarray(times), came
        at = self.trajectory.at(np.asarray(times))
        return data, np.c_[at.positions_xyz, at.orientations_quat_wxyz], np.asarray(times)

    def close(self) -> None:
        self._traces.close()


def _stack(traces, header):
    if header is None:
        return None
    if not traces:
        return np.zeros((0, header.n_samples), np.float32), np.zeros((0, 7)), np.zeros(0)
    return (np.stack([t.samples for t in traces]), np.stack([t.pose for t in traces]),
            np.array([t.time_s for t in traces]))


class SourceReader:
    """Polls ``source`` in a thread of its own, so that each batch of traces is stamped with the time it came
    (``clock()``), not the time the main loop, busy migrating or detecting, gets to it: the latency live mode
    reports counts the time traces wait in its queue. The migration kernel, NumPy's FFT and PyTorch let go of
    Python's lock while they work, so the thread keeps reading beside them. What the source raises (a broken
    stream, no connection) is raised again by :meth:`take`."""

    def __init__(self, source, *, poll_s: float = 0.005, clock=time.monotonic):
        import queue
        import threading

        self.source = source
        self.poll_s = poll_s
        self.clock = clock
        self._queue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._finished = threading.Event()  # the thread is over: the source ended, failed or was stopped
        self._arrived = threading.Event()  # something was queued since the last take
        self._error = None
        self.last_arrival = None  #: when the newest batch came (``clock()``), None before the first
        self._thread = threading.Thread(target=self._run, name="gpr3d-live-reader", daemon=True)
        self._thread.start()

    @property
    def header(self):
        return self.source.header

    def _run(self):
        try:
            while not self._stop.is_set():
                got = self.source.poll()
                if got is not None and len(got[0]):
                    self.last_arrival = self.clock()
                    self._queue.put((got, self.last_arrival))
                    self._arrived.set()
                if self.source.ended:
                    break
                if got is None or not len(got[0]):
                    self._stop.wait(self.poll_s)
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread, which raises it
            self._error = exc
        finally:
            self._finished.set()
            self._arrived.set()

    def wait(self, timeout_s: float) -> None:
        """Return once something is queued (or the thread is over), at the latest after ``timeout_s``."""
        self._arrived.wait(timeout_s)

    def take(self) -> list:
        """Every batch read so far, ``[((data, poses, times[, came]), arrival), ...]`` (``came``: when each trace came,
        where a source held traces back for their poses); the source's error once everything read before it has
        been taken."""
        import queue

        self._arrived.clear()
        out = []
        try:
            while True:
                out.append(self._queue.get_nowait())
        except queue.Empty:
            pass
        if self._finished.is_set():
            self._arrived.set()  # (nothing more will come: a wait returns at once)
        if not out and self._error is not None and self._finished.is_set():
            raise self._error
        return out

    @property
    def waiting(self) -> bool:
        """Batches read and not yet taken."""
        return not self._queue.empty()

    @property
    def ended(self) -> bool:
        """The source has ended and everything it gave has been taken."""
        return self._finished.is_set() and self._error is None and self._queue.empty() and self.source.ended

    def close(self) -> None:
        """Stop the thread, then close the source."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.source.close()


def _bag_flags(bag: dict) -> str:
    """The command line's names of a bag's settings (``dt_s`` -> ``--dt``, ``trace_topic`` -> ``--trace-topic``)."""
    return ", ".join(sorted("--" + k.removesuffix("_s").replace("_", "-") for k in bag))


def open_source(source: str, *, poses=None, channel: int = 0, offset_m: float | None = None,
                frequency_hz: float | None = None, connect_s: float = 10.0, bag: dict | None = None,
                fuse: dict | None = None):
    """The source of a live run.

    Parameters
    ----------
    source : str or Path
        ``tcp://HOST:PORT`` (the trace stream of :mod:`gpr3d.io.stream`, each trace with its pose), a DZT or
        pulseEKKO DT1 file the radar is writing, or a ROS bag (a ``.bag`` file or a ROS 2 bag folder) to replay.
    poses : str or Path, optional
        With a growing file: the TUM trajectory written beside it (pose ``i`` for trace ``i``); with a bag: a TUM
        trajectory interpolated at the traces' stamps instead of the bag's pose topic; never with ``tcp://``.
    channel : int
        The DZT's channel.
    offset_m : float, optional
        The antenna's transmitter-receiver offset (m; default: a DT1's HD header's separation, else 0; a stream's
        header gives its own).
    frequency_hz : float, optional
        The DZT antenna's centre frequency (default: from the antenna's name in the header).
    connect_s : float
        How long a ``tcp://`` source keeps trying to connect (s).
    bag : dict, optional
        A bag's settings for :class:`BagSource` (``dt_s``, ``trace_topic``, ``pose_topic``, ``samples_per_trace``,
        ``speed``, ``eps_r``, ``fuse``); a growing DT1 takes ``dt_s`` alone (where no HD header is beside it).
    fuse : dict, optional
        Fuse the antenna's poses as they come (``rig``, ``still_s``; a bag's also ``imu_topic``,
        ``odometry_topic``): from a bag's IMU and odometry topics, or from a ``tcp://`` stream's sensor messages.

    Returns
    -------
    TCPSource, FileSource or BagSource
        Polled by :func:`run_live`.

    Raises
    ------
    GPR3DError
        A malformed ``tcp://`` address, ``poses`` with a stream, a file that is no DZT or DT1, or one without
        poses.
    """
    if fuse is not None:
        fuse = dict(fuse)
        topics = sorted(k for k in fuse if k.endswith("_topic"))
        if topics and (str(source).startswith("tcp://") or not (Path(source).suffix.lower() == ".bag"
                                                                or (Path(source) / "metadata.yaml").is_file())):
            raise GPR3DError(f"{', '.join('--' + k.replace('_', '-') for k in topics)} are for a ROS bag")
    if str(source).startswith("tcp://"):
        host, _, port = str(source)[6:].rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise GPR3DError(f"{source}: expected tcp://HOST:PORT with a port in 1..65535")
        if poses is not None:
            raise GPR3DError("--poses is for a growing file: a tcp:// stream carries each trace's pose")
        if bag:
            raise GPR3DError(f"{source}: {_bag_flags(bag)} are for a ROS bag (a .bag file or a ROS 2 bag folder)")
        return TCPSource(host, int(port), connect_s=connect_s, fuse=fuse)
    p = Path(source)
    if p.suffix.lower() == ".bag" or (p / "metadata.yaml").is_file():
        settings = dict(bag or {})
        if fuse is not None:
            settings["fuse"] = fuse
        if "dt_s" not in settings:
            raise GPR3DError(f"{source}: a bag's traces carry no sample interval: give it (--dt, in ns)")
        return BagSource(p, poses=poses, offset_m=offset_m or 0.0, frequency_hz=frequency_hz, **settings)
    dt_s = None
    if p.suffix.lower() == ".dt1" and bag and set(bag) == {"dt_s"}:
        dt_s = bag["dt_s"]  # (a DT1 whose HD header is not there yet)
    elif bag:
        raise GPR3DError(f"{source}: {_bag_flags(bag)} are for a ROS bag (a .bag file or a ROS 2 bag folder)")
    if fuse is not None:
        raise GPR3DError(f"{source}: --fuse is for a ROS bag or a tcp:// stream carrying IMU samples (a growing "
                         "file's poses come from --poses)")
    return FileSource(source, poses, channel=channel, offset_m=offset_m, frequency_hz=frequency_hz, dt_s=dt_s)


# -- the engine ----------------------------------------------------------------------------------------------------

class _Window:
    """Rows numbered from ``first`` on (float32, ``width`` wide): appended at the end, forgotten from the front
    (:meth:`drop_before`), read by their numbers (:meth:`rows`). Both are amortised O(rows moved): the buffer
    doubles when full, and the rows still kept move to its front when they would fit its first half again. (A
    concatenation at every arrival copies every row kept at every arrival: where detection fell behind, the
    rows kept grew with the backlog and each arrival's copy with them.)"""

    def __init__(self, width: int, rows=None):
        self._a = np.zeros((1024, width), np.float32)
        self._lo = self._hi = 0
        self.first = 0  #: the number of the first row kept
        if rows is not None:
            self.append(rows)

    @property
    def end(self) -> int:
        """One past the number of the last row."""
        return self.first + self._hi - self._lo

    def __len__(self) -> int:
        return self._hi - self._lo

    def append(self, rows) -> None:
        rows = np.asarray(rows, np.float32)
        k, n = len(rows), self._hi - self._lo
        if self._hi + k > len(self._a):
            if 2 * (n + k) <= len(self._a):
                self._a[:n] = self._a[self._lo: self._hi]  # (numpy copies overlapping slices correctly)
            else:
                grown = np.zeros((2 * (n + k), self._a.shape[1]), np.float32)
                grown[:n] = self._a[self._lo: self._hi]
                self._a = grown
            self._lo, self._hi = 0, n
        self._a[self._hi: self._hi + k] = rows
        self._hi += k

    def drop_before(self, i: int) -> None:
        """Forget the rows numbered below ``i``."""
        i = min(max(int(i), self.first), self.end)
        self._lo += i - self.first
        self.first = i

    def rows(self, a: int, b: int) -> np.ndarray:
        """Rows ``a`` .. ``b - 1`` by number (a view: valid until the next :meth:`append`)."""
        if a < self.first or b > self.end or a > b:
            raise IndexError(f"rows {a}..{b} asked of rows {self.first}..{self.end}")
        return self._a[self._lo + a - self.first: self._lo + b - self.first]


class _DetectorThread:
    """Runs ``run(a, data)`` on the windows given to :meth:`submit`, one after the other in a thread of its own,
    and hands their results back in the same order (:meth:`take`). The detector's network (ONNX Runtime or
    PyTorch) lets go of Python's lock while it computes, so the windows run beside the migration and the refreshes:
    on 2 cores neither fills both. What ``run`` raises is raised again by :meth:`take`."""

    #: windows given to the thread and not yet taken back, at most: one running, one waiting (the detector is
    #: never idle while windows are full); more wait in the raw traces, where the backlog rules see them
    QUEUED = 2

    def __init__(self, run):
        import threading
        from collections import deque

        self._run_window = run
        self._jobs: deque = deque()
        self._done: deque = deque()
        self._cv = threading.Condition()
        self._closed = False
        self.in_flight = 0  # submitted and not yet taken back
        self._thread = threading.Thread(target=self._loop, name="gpr3d-live-detector", daemon=True)
        self._thread.start()

    def submit(self, a: int, data: np.ndarray) -> None:
        with self._cv:
            self._jobs.append((a, data))
            self.in_flight += 1
            self._cv.notify_all()

    def _loop(self):
        while True:
            with self._cv:
                while not self._jobs and not self._closed:
                    self._cv.wait()
                if self._closed:
                    return
                a, data = self._jobs[0]
            try:
                got = (a, self._run_window(a, data), None)
            except BaseException as exc:  # noqa: BLE001 - handed to the main thread, which raises it
                got = (a, None, exc)
            with self._cv:
                self._jobs.popleft()
                self._done.append(got)
                self._cv.notify_all()

    def take(self) -> list:
        """``[(a, result), ...]`` of the windows finished since the last take, in the order they were given."""
        with self._cv:
            done = list(self._done)
            self._done.clear()
            self.in_flight -= len(done)
        for _, _, exc in done:
            if exc is not None:
                raise exc
        return [(a, r) for a, r, _ in done]

    def wait(self, left: int) -> None:
        """Return once at most ``left`` of the windows given are not finished."""
        with self._cv:
            while len(self._jobs) > left:
                self._cv.wait()

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify_all()
        self._thread.join(timeout=5.0)


class LiveReconstruction:
    """The state of a live run: feed it batches of raw traces with poses (:meth:`add`), call :meth:`step` to
    process what is ready, :meth:`finish` at the end."""

    def __init__(self, header: StreamHeader, cfg: LiveConfig, out, *, detector=None, log=None):
        from gpr3d.migration.config import ReconstructConfig
        from gpr3d.migration.reconstruct import check_config

        self.h = header
        self.cfg = cfg
        rc = cfg.reconstruct or ReconstructConfig()
        eps = rc.eps_r or header.eps_r
        if eps is None:
            raise GPR3DError("no eps_r: the stream's header gives none; give --eps-r")
        if rc.aperture_deg is None:
            raise GPR3DError("live mode needs an aperture (--aperture > 0): it bounds the voxels each trace reaches")
        if rc.method != "backprojection":
            raise GPR3DError("live mode migrates by back projection (--method backprojection)")
        self.rc = replace(rc, eps_r=float(eps), lattice=True, background_window=cfg.background_window,
                          background_trailing=cfg.background_trailing, remove_background=True,
                          coarse_to_fine=False,  # (every voxel is migrated as the traces come)
                          signal_depth=False)  # (where the signal ends is not known before the survey does)
        check_config(self.rc)
        if self.rc.spacing_m is None:  # as a batch reconstruct of the same record sizes its voxels (eps_r checked)
            from gpr3d.migration.reconstruct import voxel_spacing_m

            self.rc = replace(self.rc, spacing_m=voxel_spacing_m(header.frequency_hz, float(eps))[0])
        self.eps = float(eps)
        self.v = velocity_from_eps_r(self.eps)
        self.out = Path(out)
        self.tiles_dir = self.out / "tiles"
        self.detector = detector if cfg.detect else None
        self.log = log or (lambda msg: None)
        w = cfg.background_window
        # the traces before and after each one that its background window spans (scipy's centred window:
        # i - w//2 .. i + w - 1 - w//2; the trailing one: i - w + 1 .. i)
        self.h1, self.h2 = (w - 1, 0) if cfg.background_trailing else (w // 2, w - 1 - w // 2)
        self.t0_s = None
        self.n_out = None
        self.raw_pending: list = []  # raw traces waiting for time zero
        self.n_in = 0
        # the traces cut at time zero, by number (kept while the background window may still need them)
        self.cut = _Window(header.n_samples)
        self.n_final = 0  # traces migrated
        self._poses = GrowingRows(7)  # every trace's pose (x y z qw qx qy qz): the final grid covers them all
        self._arrival = GrowingRows(1)  # the monotonic time each trace arrived
        self.tiles: dict = {}  # (a, b) -> [image, fold]
        self.dirty: set = set()  # the tiles traces were added to since the last refresh
        self.on_disk: set = set()
        self.peak_tiles = 0
        self.fold_max = 0.0
        self.grid_base = None
        # detection: raw traces kept for the next window
        self.raw_tail = _Window(header.n_samples)
        self.next_window = 0  # where the next window starts
        self.det_end = 0  # where the last window ended
        self.detect_thinned = 0  # windows taken without overlap (the detector behind)
        self.detect_skipped = 0  # traces no window saw (the detector far behind)
        self.detections: list = []
        self._det_window: list = []  # the window each kept detection came from (its first trace)
        self.targets: list = []
        self.latencies: list = []
        self._worker = _DetectorThread(self._found_in) if self.detector is not None and cfg.detect_thread else None
        #: called before a refresh to add the traces that came meanwhile (run_live: what the reader has queued)
        self.intake = None
        #: whether traces wait to be taken in (run_live: the reader's queue): the detector then yields to a due refresh
        self.waiting = None
        self.last_refresh = None  # when the last refresh started
        self.refresh_costs: list = []  # how long the last few refreshes took (s)
        self.n_refreshed = 0  # traces migrated at the last refresh
        # the seconds spent migrating, running the detector and refreshing the targets (the summary's ``busy_s``)
        self.migrate_s = self.detect_s = self.refresh_s = 0.0

    @property
    def poses(self) -> np.ndarray:
        """``(n_traces_in, 7)``: each trace's pose ``x y z qw qx qy qz``."""
        return self._poses[:]

    @property
    def arrival(self) -> np.ndarray:
        """``(n_traces_in,)``: when each trace arrived (monotonic seconds)."""
        return self._arrival[:, 0]

    # the depth axis, the reach of a trace, the tile lattice ---------------------------------------------------
    def _setup_grid(self):
        from gpr3d.migration.reconstruct import record_depth_m

        rc = self.rc
        depth = rc.max_depth_m or record_depth_m(self.v, self.n_out * self.h.dt_s, rc.air_gap_m)
        dd = rc.depth_spacing_m or rc.spacing_m
        nd = int(np.floor((depth - dd) / dd)) + 1
        if nd < 2:
            raise GPR3DError(f"the record reaches {depth:.3f} m: too shallow for depth steps of {dd:g} m")
        self.depth_m = depth
        self.grid_base = Grid3D(0.0, 0.0, dd, rc.spacing_m, rc.spacing_m, dd, 1, 1, nd)
        # how far from its antennas a trace reaches (the aperture cone at the deepest voxel, or its radius where
        # that is the narrower), with a cell to spare
        cone = self.grid_base.depth[-1] * math.tan(math.radians(rc.aperture_deg))
        self.reach = (cone if rc.aperture_m is None else min(cone, rc.aperture_m)) + 2 * rc.spacing_m

    def add(self, data, poses, *, now=None):
        """Raw traces ``(k, n_samples)`` with poses ``(k, 7)`` (``x y z qw qx qy qz``), arrived at ``now``
        (monotonic seconds, or one time per trace; default: now)."""
        data = np.asarray(data, np.float32)
        k = len(data)
        if k == 0:
            return
        if data.shape[1] != self.h.n_samples:
            raise InvalidDataError(f"traces of {data.shape[1]} samples where the stream has {self.h.n_samples}")
        if not np.all(np.isfinite(data)):
            bad = int(np.nonzero(~np.all(np.isfinite(data), axis=1))[0][0]) + self.n_in
            raise InvalidDataError(f"trace {bad}: non-finite samples")
        now = time.monotonic() if now is None else now
        p = np.asarray(poses, float).reshape(k, 7).copy()
        norm = np.linalg.norm(p[:, 3:], axis=1)
        bad = np.nonzero(~np.all(np.isfinite(p), axis=1) | ~(norm > 1e-9))[0]
        if bad.size:
            raise InvalidDataError(f"trace {int(bad[0]) + self.n_in}: its pose is not finite or its quaternion zero")
        p[:, 3:] /= norm[:, None]
        self._poses.append(p)
        self._arrival.append(np.broadcast_to(np.asarray(now, float), (k,)))
        self.n_in += k
        if self.detector is not None:
            self.raw_tail.append(data)
        if self.t0_s is None:
            self.raw_pending.append(data)
            if self.n_in >= self.cfg.time_zero_traces:
                self._fix_time_zero()
        else:
            self.cut.append(self._cut(data))

    def _fix_time_zero(self):
        from gpr3d.core.survey import Survey
        from gpr3d.migration.reconstruct import time_zero_search_s
        from gpr3d.processing.steps import time_zero

        raw = np.concatenate(self.raw_pending)
        self.raw_pending = []
        if self.rc.time_zero_s is not None:
            t0 = float(self.rc.time_zero_s)
        elif self.rc.time_zero == "none":
            t0 = 0.0
        else:
            s = Survey(data=raw, dt_s=self.h.dt_s, offset_m=self.h.offset_m)
            t0 = float(time_zero(s, method=self.rc.time_zero, search_s=time_zero_search_s(s), shift=False)[0]["t0_s"])
        self.t0_s = t0
        self.rc = replace(self.rc, time_zero_s=t0)
        self.n_out = int(np.floor(self.h.n_samples - 1 - t0 / self.h.dt_s + 1e-9)) + 1
        self._setup_grid()
        self.cut = _Window(self.n_out, self._cut(raw))
        self.log(f"time zero {t0 * 1e9:.3f} ns (from the first {len(raw)} traces); eps_r {self.eps:g}; "
                 f"depth {self.depth_m:.2f} m")

    def _cut(self, data):
        from gpr3d.processing.timezero import shift_traces

        return shift_traces(data, self.t0_s / self.h.dt_s)

    def _readiness(self, ended: bool):
        """``(n_cut, ready, short)``: the traces cut so far, those whose background is final, and whether a centred
        window spans the whole survey so far."""
        n_cut = self.cut.end
        ready = n_cut if ended else n_cut - self.h2
        short = not self.cfg.background_trailing and n_cut < self.cfg.background_window
        if short and not ended:
            ready = 0  # wait: the survey may yet end shorter than the window
        return n_cut, ready, short

    def step(self, *, ended: bool = False) -> int:
        """Migrate the traces whose background is final (once ``min_batch`` of them wait, or a refresh is due),
        refresh the targets when due (taking in first what ``intake`` has waiting), run the detector on the
        full windows. Returns how many traces were migrated and windows detected."""
        if self.t0_s is None:
            if not ended or not self.raw_pending:
                return 0
            self._fix_time_zero()
        w = self.cfg.background_window
        n_cut, ready, short = self._readiness(ended)
        work = 0
        if ended or ready - self.n_final >= self.cfg.min_batch or self._refresh_due():
            work += self._migrate_to(ready, n_cut, w, short, refresh=not ended)
        # the targets before the detector: what a user waits for on screen comes first. The refresh takes in the
        # traces that came while this step worked, and shows every trace ready by then
        if not ended and self._refresh_due() and self.intake is not None:
            self.intake()
            n_cut, ready, short = self._readiness(ended)
        if ready > self.n_refreshed and (ended or self._refresh_due()):
            work += self._migrate_to(ready, n_cut, w, short)
            self.refresh()
        if self.detector is not None:
            work += self._detect(ended, ready)
        return work

    def _refresh_due(self) -> bool:
        """The refresh's period, from the start of the last one, is over: ``refresh_s``, or longer where a refresh
        costs more than a third of it (the targets' extraction must not starve the migration; the cost is the
        median of the last five, so that one refresh slowed by the machine does not hold the next one back)."""
        if self.last_refresh is None:
            return True
        cost = float(np.median(self.refresh_costs)) if self.refresh_costs else 0.0
        return time.monotonic() - self.last_refresh >= max(self.cfg.refresh_s, 3.0 * cost)

    def _migrate_to(self, ready, n_cut, w, short, *, refresh: bool = False) -> int:
        """Migrate every trace up to ``ready`` (in batches of at most ``max_batch``; with ``refresh``, a backlog
        shows the targets of what is migrated so far between its batches when a refresh falls due); returns how
        many."""
        from gpr3d.processing.background import moving_background, remove_background

        done = 0
        while self.n_final < ready:
            a = self.n_final
            b = min(ready, a + self.cfg.max_batch)
            lo = max(0, a - self.h1)
            hi = min(n_cut, b + self.h2)
            # the batch's background on a slice holding every trace the rows' windows span: the same numbers (the
            # slice's ends pad only where the survey's own do); a survey shorter than the window loses its mean
            x = self.cut.rows(lo, hi)
            if short:
                traces = remove_background(x)
            else:
                bg = moving_background(x, w, trailing=self.cfg.background_trailing)
                traces = (x - bg).astype(np.float32)
            traces = traces[a - lo: b - lo]
            self._migrate(traces, self.poses[a:b])
            self.n_final = b
            done += b - a
            self.cut.drop_before(self.n_final - self.h1)
            self._evict()
            if refresh and self.n_final < ready and self._refresh_due():
                self.refresh()
        return done

    def _migrate(self, traces, poses):
        from gpr3d.migration.operator import BackProjection, antenna_positions

        t = time.perf_counter()
        tx, rx = antenna_positions(poses[:, :3], poses[:, 3:], self.h.offset_m)
        g, T = self.grid_base, self.cfg.tile_voxels
        both = np.concatenate([tx, rx])[:, :2]
        lo = np.floor((both.min(axis=0) - self.reach) / g.dx).astype(int) // T
        hi = np.floor((both.max(axis=0) + self.reach) / g.dx).astype(int) // T
        na, nb = hi - lo + 1
        grid = replace(g, x0=float(lo[0] * T) * g.dx, y0=float(lo[1] * T) * g.dy, nx=int(na * T), ny=int(nb * T))
        op = BackProjection(grid, tx, rx, dt_s=self.h.dt_s, n_samples=self.n_out, t0_s=0.0, eps_r=self.eps,
                            aperture_deg=self.rc.aperture_deg, aperture_m=self.rc.aperture_m,
                            obliquity=self.rc.obliquity, spreading=self.rc.spreading, air_gap_m=self.rc.air_gap_m,
                            engine=self.rc.engine)
        img, fold = op.adjoint(traces, with_fold=True)
        for i in range(na):
            for j in range(nb):
                sl = (slice(i * T, (i + 1) * T), slice(j * T, (j + 1) * T))
                f = fold[sl]
                if not f.any():
                    continue
                key = (int(lo[0] + i), int(lo[1] + j))
                self.dirty.add(key)
                tile = self._tile(key)
                tile[0] += img[sl]
                tile[1] += f
                self.fold_max = max(self.fold_max, float(tile[1].max()))
        self.peak_tiles = max(self.peak_tiles, len(self.tiles))
        self.migrate_s += time.perf_counter() - t

    def _tile(self, key):
        tile = self.tiles.get(key)
        if tile is None:
            if key in self.on_disk:
                with np.load(self._tile_path(key)) as z:
                    tile = [z["image"].copy(), z["fold"].copy()]
            else:
                shape = (self.cfg.tile_voxels, self.cfg.tile_voxels, self.grid_base.nd)
                tile = [np.zeros(shape, np.float32), np.zeros(shape, np.float32)]
            self.tiles[key] = tile
        return tile

    def _tile_path(self, key):
        return self.tiles_dir / f"tile_{key[0]}_{key[1]}.npz"

    def _save_tile(self, key, tile):
        import os

        self.tiles_dir.mkdir(parents=True, exist_ok=True)
        path = self._tile_path(key)
        tmp = path.with_name(path.name + ".part.npz")
        np.savez(tmp, image=tile[0], fold=tile[1])
        os.replace(tmp, path)
        self.on_disk.add(key)

    def _evict(self):
        """Tiles no trace of the last ``background_window`` can reach go to disk."""
        if not self.tiles or self.n_final == 0:
            return
        recent = self.poses[max(0, self.n_final - self.cfg.background_window): self.n_final, :2]
        lo = recent.min(axis=0) - self.reach - self.h.offset_m
        hi = recent.max(axis=0) + self.reach + self.h.offset_m
        side = self.cfg.tile_voxels * self.grid_base.dx
        for key in list(self.tiles):
            x0, y0 = key[0] * side, key[1] * side
            if x0 > hi[0] or x0 + side < lo[0] or y0 > hi[1] or y0 + side < lo[1]:
                self._save_tile(key, self.tiles.pop(key))

    # detection ---------------------------------------------------------------------------------------------------
    def _detect(self, ended, ready):
        """Every full window not yet detected, one by one (a window's detections do not depend on how the
        traces arrived: the detector prepares each window on its own; one call a window costs what one call over
        several does, measured), until a refresh is due for traces up to ``ready`` or for traces waiting in the
        reader (those wait for the next step); at the end, one window over the last traces. Returns how many
        windows ran.

        A detector that cannot keep up falls behind by at most ``2 x detect_backlog`` traces (the raw traces it
        has yet to see are held in memory): beyond ``detect_backlog`` it takes windows without overlap (each trace
        once), beyond twice that it skips ahead to the newest ``detect_backlog`` traces; both are counted
        (``detect_thinned`` windows, ``detect_skipped`` traces seen by no window) and reported."""
        win = self.detector.window.traces
        step = max(1, int(round(win * (1 - self.detector.window.overlap))))
        backlog = max(int(self.cfg.detect_backlog), 2 * win)
        n = self.raw_tail.end
        ran = 0
        worker = self._worker
        if worker is not None:
            self._collect()
        while n - self.next_window >= win:
            if worker is None:
                if not ended and self._refresh_due() and (ready > self.n_refreshed or self._waiting()):
                    break
            elif worker.in_flight >= _DetectorThread.QUEUED:
                if not ended:
                    break  # (the windows wait for the thread: the detector is behind by what waits here)
                worker.wait(worker.in_flight - 1)
                self._collect()
            if n - self.next_window > 2 * backlog:
                start = (n - backlog) // step * step
                self.detect_skipped += max(0, start - self.det_end)
                self.next_window = start
            self._run_window(self.next_window, self.next_window + win)
            self.det_end = self.next_window + win
            thin = n - self.next_window > backlog
            self.detect_thinned += thin
            self.next_window += win if thin else step
            ran += 1
        if ended and n > self.det_end:
            self._run_window(max(0, n - win), n)
            self.det_end = self.next_window = n
            ran += 1
        if ended and worker is not None:
            worker.wait(0)
            self._collect()
        self.raw_tail.drop_before(self.next_window - win)  # (the last window at the end may reach back)
        return ran

    def _run_window(self, a, b):
        """The detector on traces ``a .. b - 1``: now, or queued for the detector's thread (a copy of them)."""
        if self._worker is None:
            self._detect_span(a, b)
        else:
            self._worker.submit(a, self.raw_tail.rows(a, b).copy())

    def _collect(self):
        """The detections of the windows the detector's thread has finished, in their order."""
        for a, found in self._worker.take():
            for t in found:
                self._add_detection(t, a)

    def close(self):
        """Stop the detector's thread (the windows it has not run are dropped)."""
        if self._worker is not None:
            self._worker.close()

    def _waiting(self) -> bool:
        return bool(self.waiting is not None and self.waiting())

    def _detect_span(self, a, b):
        for t in self._found_in(a, self.raw_tail.rows(a, b)):
            self._add_detection(t, a)

    def _found_in(self, a, data) -> list:
        """The detector's targets in ``data``, the raw traces from number ``a`` on, placed in the stream's traces."""
        from gpr3d.core.survey import Survey

        t0 = time.perf_counter()
        s = Survey(data=data, dt_s=self.h.dt_s, frequency_hz=self.h.frequency_hz, offset_m=self.h.offset_m)
        found = self.detector.detect(s, score_threshold=self.cfg.score, input_name=self.h.name)
        out = []
        for t in found["targets"]:
            t = dict(t)
            t["box"] = [t["box"][0] + a, t["box"][1], t["box"][2] + a, t["box"][3]]
            t["apex_trace"] += a
            out.append(t)
        self.detect_s += time.perf_counter() - t0  # (only this thread, or only the main one, adds to it)
        return out

    def _add_detection(self, t, window_start=0):
        """Keep ``t`` (found in the window starting at trace ``window_start``) unless a kept box of the same
        hyperbola (IoU > 0.5, from an overlapping window) scores higher; replace that one otherwise. Only the
        windows that overlap this one are looked at (the kept boxes are in the order of their windows)."""
        b = t["box"]
        reach = window_start - (self.detector.window.traces if self.detector is not None else np.inf)
        for i in range(len(self.detections) - 1, -1, -1):
            if self._det_window[i] <= reach:
                break  # this window and all before it end before ``t``'s begins
            u = self.detections[i]
            c = u["box"]
            iw = min(b[2], c[2]) - max(b[0], c[0])
            ih = min(b[3], c[3]) - max(b[1], c[1])
            if iw <= 0 or ih <= 0:
                continue
            inter = iw * ih
            iou = inter / ((b[2] - b[0]) * (b[3] - b[1]) + (c[2] - c[0]) * (c[3] - c[1]) - inter)
            if iou > 0.5:
                if t["score"] > u["score"]:
                    self.detections[i] = t
                return
        self.detections.append(t)
        self._det_window.append(window_start)

    # targets and reports -----------------------------------------------------------------------------------------
    def _assemble(self, grid, tiles):
        """The image and fold on ``grid`` (a lattice grid) from ``tiles`` (key -> [image, fold] or a path)."""
        T = self.cfg.tile_voxels
        img = np.zeros(grid.shape, np.float32)
        fold = np.zeros(grid.shape, np.float32)
        gx, gy = int(round(grid.x0 / grid.dx)), int(round(grid.y0 / grid.dy))
        for key, tile in tiles.items():
            ax, ay = key[0] * T - gx, key[1] * T - gy
            x0, x1 = max(ax, 0), min(ax + T, grid.nx)
            y0, y1 = max(ay, 0), min(ay + T, grid.ny)
            if x0 >= x1 or y0 >= y1:
                continue
            if not isinstance(tile, list):
                with np.load(tile) as z:
                    tile = [z["image"], z["fold"]]
            img[x0:x1, y0:y1] = tile[0][x0 - ax:x1 - ax, y0 - ay:y1 - ay]
            fold[x0:x1, y0:y1] = tile[1][x0 - ax:x1 - ax, y0 - ay:y1 - ay]
        return img, fold

    def _final_grid(self):
        return Grid3D.covering(self.poses[: self.n_final, :3], depth_m=self.depth_m, spacing_m=self.rc.spacing_m,
                               depth_spacing_m=self.rc.depth_spacing_m, pad_m=self.rc.pad_m, lattice=True)

    def _refresh_regions(self) -> list:
        """The parts of the lattice a refresh looks at: the tiles traces were added to since the last refresh, with
        the tiles in memory next to them, in groups that touch (a cart that jumped, or crossed back, gives two);
        each a ``(key_lo, key_hi)`` box of tile keys, inclusive."""
        from scipy.ndimage import find_objects, label

        near = {(a + da, b + db) for a, b in self.dirty for da in (-1, 0, 1) for db in (-1, 0, 1)}
        keys = np.array(sorted(near & set(self.tiles)), dtype=int).reshape(-1, 2)
        if not len(keys):
            return []
        k0 = keys.min(axis=0)
        occupied = np.zeros(tuple(keys.max(axis=0) - k0 + 1), bool)
        occupied[tuple((keys - k0).T)] = True
        groups, _ = label(occupied, structure=np.ones((3, 3), bool))
        return [(k0 + np.array([sl[0].start, sl[1].start]), k0 + np.array([sl[0].stop - 1, sl[1].stop - 1]))
                for sl in find_objects(groups)]

    def refresh(self):
        """The targets where traces were added since the last refresh (``_refresh_regions``), on the tiles in
        memory there; the targets elsewhere are kept from earlier refreshes (a target reaching into a refreshed
        region is replaced by what the region shows now); and ``live.json``."""
        from gpr3d.migration.masking import image_envelope
        from gpr3d.migration.reconstruct import normalise_by_fold, volume_targets

        t_start = time.monotonic()
        T, g = self.cfg.tile_voxels, self.grid_base
        p = self.poses[: self.n_final, :2]
        for k_lo, k_hi in self._refresh_regions():
            # the region's tiles, cut down to the antenna positions inside them and the pad (as reconstruct's grid
            # covers the positions): the tiles reach an aperture further, where little is seen
            lo_m, hi_m = k_lo * T * g.dx, (k_hi + 1) * T * g.dx
            pts = p[np.all((p >= lo_m) & (p < hi_m), axis=1)]
            if len(pts) < 2:
                continue
            i0 = np.maximum(np.floor((pts.min(axis=0) - self.rc.pad_m) / g.dx).astype(int), k_lo * T)
            i1 = np.minimum(np.ceil((pts.max(axis=0) + self.rc.pad_m) / g.dx).astype(int) + 1, (k_hi + 1) * T)
            grid = replace(g, x0=float(i0[0]) * g.dx, y0=float(i0[1]) * g.dy, nx=int(i1[0] - i0[0]),
                           ny=int(i1[1] - i0[1]))
            img, fold = self._assemble(grid, self.tiles)
            img, _ = normalise_by_fold(img, fold, self.rc.normalize, fold_max=self.fold_max)
            env = image_envelope(img, chunk_voxels=1_000_000)  # (slabs of 8 MB: reused, see keep_memory)
            # the final extraction's settings but a coarser Hough angle step (a third of the time) and at most
            # preview_max_peaks peaks (43 % less again), each measured on the benchmark's survey
            # (benchmarks/bench_live.py) with the same targets at every refresh
            found = volume_targets(env, grid, self.rc, self.v, self.h.frequency_hz,
                                   angle_step_deg=self.cfg.preview_angle_step_deg,
                                   max_peaks=self.cfg.preview_max_peaks)
            lo_m, hi_m = i0 * g.dx, i1 * g.dx

            def reaches(t):  # (a line: along its length, not only at its ends)
                ends = np.asarray(t.points_xyz, float).reshape(-1, 3)[:, :2]
                xy = ends[:1] + np.linspace(0.0, 1.0, 65)[:, None] * (ends[-1:] - ends[:1])
                return bool(np.any(np.all((xy >= lo_m) & (xy < hi_m), axis=1)))

            self.targets = [t for t in self.targets if not reaches(t)] + found
        self.dirty.clear()
        self._write_status()
        behind = float(self.arrival[self.n_in - 1] - self.arrival[self.n_final - 1]) if self.n_final else 0.0
        self.log(f"  {self.n_in:,} traces in, {self.n_final:,} migrated ({behind:.2f} s behind the newest), "
                 f"{len(self.targets)} targets, {len(self.detections)} detections, {len(self.tiles)} tiles in memory")
        done = time.monotonic()
        if self.n_final > self.n_refreshed:
            # the oldest trace this refresh brings in waited longest: from its arrival to targets that include it
            self.latencies.append(done - float(self.arrival[self.n_refreshed]))
        self.n_refreshed = self.n_final
        self.refresh_costs = [*self.refresh_costs[-4:], done - t_start]
        self.refresh_s += done - t_start
        self.last_refresh = t_start

    def status(self) -> dict:
        from gpr3d.migration.targets import targets_to_json

        return {"n_traces_in": self.n_in, "n_traces_migrated": self.n_final,
                "time_zero_s": self.t0_s, "eps_r": self.eps,
                "tiles_in_memory": len(self.tiles), "tiles_on_disk": len(self.on_disk),
                "detect_thinned": self.detect_thinned, "detect_skipped": self.detect_skipped,
                "targets": targets_to_json(self.targets), "detections": self.detections, "config": asdict(self.rc)}

    def _write_status(self):
        # (compact: rewritten at every refresh, and it grows with the survey's detections: at 2,600 of them,
        # indented JSON measured 29 ms a refresh, compact 11 ms; the last one, at the end, is indented)
        self.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.out / "live.json", json.dumps(self.status(), separators=(",", ":")))

    def finish(self, *, source: str = ""):
        """Everything left migrated; the final volume over every antenna position (when it is at most
        ``final_volume_voxels``), finished as ``reconstruct`` finishes its own, written to ``OUT``. Returns the
        :class:`~gpr3d.migration.reconstruct.Reconstruction` (None when the volume is too big: its tiles stay in
        ``OUT/tiles``)."""
        from gpr3d.migration.masking import image_envelope
        from gpr3d.migration.reconstruct import Reconstruction, normalise_by_fold, volume_targets, write_reconstruction

        try:
            self.step(ended=True)
        finally:
            self.close()
        if self.n_final == 0:
            raise GPR3DError("no traces arrived: nothing to migrate")
        grid = self._final_grid()
        if grid.size > self.cfg.final_volume_voxels:
            for key, tile in list(self.tiles.items()):
                self._save_tile(key, tile)
            self.log(f"the final volume ({grid.nx} x {grid.ny} x {grid.nd}) is larger than "
                     f"{self.cfg.final_volume_voxels:,} voxels: its tiles are in {self.tiles_dir}")
            return None
        tiles = {k: self._tile_path(k) for k in self.on_disk}
        tiles.update(self.tiles)
        img, fold = self._assemble(grid, tiles)
        cfg = self.rc
        if cfg.normalize != "none":
            img, _ = normalise_by_fold(img, fold, cfg.normalize)
        env = image_envelope(img)
        targets = volume_targets(env, grid, cfg, self.v, self.h.frequency_hz)
        self.targets = targets
        res = Reconstruction(image=img, envelope=env, noise_map=None, fold=fold if cfg.normalize != "none" else None,
                             grid=grid, targets=targets, eps_r=self.eps, config=asdict(cfg), n_traces=self.n_final,
                             timings_s={"migrate": self.migrate_s}, updates_per_s=None, eps_r_source="live")
        write_reconstruction(res, self.out, source=source)
        return res


def _keep_freed_memory() -> bool:
    """Ask glibc's allocator to keep freed memory in the process (blocks up to 32 MB from its heap, never trimmed
    back) so that live mode's arrays, the same sizes at every batch and refresh, reuse pages already mapped.
    Returns False where there is no glibc (nothing changed)."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # (glibc's malloc.h)
    return bool(mallopt(m_mmap_threshold, 32 << 20)) and bool(mallopt(m_trim_threshold, (1 << 31) - 1))


def _warm_up(cfg: LiveConfig, detector) -> None:
    """Load the migration kernel (numba's cache), the detector's first run and the modules the first traces need
    before any trace comes: otherwise the first trace waits for them (measured: 2.3 s to the first targets, against
    0.5 s for the rest)."""
    from gpr3d.core.survey import Survey
    from gpr3d.migration.config import ReconstructConfig
    from gpr3d.migration.operator import BackProjection

    rc = cfg.reconstruct or ReconstructConfig()
    grid = Grid3D(0.0, 0.0, 0.02, 0.03, 0.03, 0.02, 8, 8, 4)
    at = np.zeros((2, 3))
    BackProjection(grid, at, at, dt_s=1e-10, n_samples=64, eps_r=4.0, aperture_deg=rc.aperture_deg or 45.0,
                   obliquity=rc.obliquity, spreading=rc.spreading, engine=rc.engine).adjoint(
        np.zeros((2, 64), np.float32), with_fold=True)
    if detector is not None and cfg.detect:
        detector.share_cores()  # (a pool spinning between windows takes the cores the migration runs on)
        detector.detect(Survey(data=np.zeros((detector.window.traces, 64), np.float32), dt_s=1e-10),
                        score_threshold=1.0)
        refiner = getattr(detector, "refiner", None)  # (refined are only the boxes reported: none above)
        if refiner is not None:
            from gpr3d.detection.refine import CROP

            refiner.predict_crops(np.zeros((2, 3, CROP, CROP), np.float32))
    from gpr3d.migration.masking import image_envelope  # (scipy.signal: a second to import, on the first refresh)
    from gpr3d.processing.background import moving_background
    from gpr3d.processing.steps import time_zero  # noqa: F401  (what the first traces need, imported now)

    image_envelope(np.zeros((2, 2, 8), np.float32))
    moving_background(np.zeros((3, 4), np.float32), 2)


def run_live(source, out, cfg: LiveConfig, *, detector=None, log=print, poll_s: float = 0.02,
             clock=time.monotonic, reader_thread: bool = True) -> LiveSummary:
    """Run live mode on ``source`` into the folder ``out`` until the stream ends or has been idle
    ``cfg.until_idle_s``.

    Parameters
    ----------
    source : TCPSource or FileSource
        From :func:`open_source`.
    out : str or Path
        The folder: ``live.json`` while running, the result files at the end (``docs/CONVENTIONS.md``).
    cfg : LiveConfig
        The settings.
    detector : Detector, optional
        The hyperbola detector run on each window (with ``cfg.detect``).
    log : callable
        Progress lines (``print``; None: silent).
    poll_s : float
        How long to wait for traces when there is nothing else to do (s).
    clock : callable
        Monotonic seconds for the arrivals, the idle time and the rate (tests give their own).
    reader_thread : bool
        Read the source in a thread of its own (:class:`SourceReader`: each trace stamped when it came). False:
        the main loop polls it between its work, stamping what it finds then (tests that script the clock).

    Returns
    -------
    LiveSummary
        Its :meth:`~LiveSummary.line` is what ``gpr3d live`` prints last.

    Raises
    ------
    GPR3DError
        No traces arrived, no connection, a stream or file that breaks its format, or settings live mode cannot
        run (no aperture, no eps_r).
    """
    made: list = []  # the LiveReconstruction once it is made: its detector's thread stops however the run ends
    try:
        return _run_live(source, out, cfg, made, detector=detector, log=log, poll_s=poll_s, clock=clock,
                         reader_thread=reader_thread)
    finally:
        for live in made:
            live.close()


def _run_live(source, out, cfg, made, *, detector, log, poll_s, clock, reader_thread) -> LiveSummary:
    log = log or (lambda msg: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    live = None
    if cfg.keep_memory:
        _keep_freed_memory()
    _warm_up(cfg, detector)
    t_start = clock()
    t_first = None  # the first trace's arrival: the idle clock and the rate start there
    last_new = t_start
    newest_arrival = None
    worked_until = -math.inf  # when the last step that did some work ended
    interrupted = False
    reader = SourceReader(source, clock=clock) if reader_thread else None

    def add(batches):
        nonlocal t_first, last_new, newest_arrival
        for got, at in batches:
            if len(got[0]):
                came = got[3] if len(got) > 3 else at  # (a fused trace came before the filter let it go)
                live.add(got[0], got[1], now=came)
                t_first = float(np.min(came)) if t_first is None else t_first
                newest_arrival = float(np.max(came))
                last_new = at

    try:
        while True:
            if reader is not None:
                batches = reader.take()
                ended = reader.ended
            else:
                got = source.poll()
                now = clock()
                batches = [(got, now)] if got is not None else []
                ended = source.ended
            if batches and live is None and source.header is not None:
                live = LiveReconstruction(source.header, cfg, out, detector=detector, log=log)
                made.append(live)
                if reader is not None:
                    live.intake = lambda: add(reader.take())  # (a due refresh takes in what came meanwhile)
                    live.waiting = lambda: reader.waiting
            add(batches)
            worked = live.step() if live is not None else 0
            if worked:
                worked_until = clock()
            if ended:
                break
            if reader is not None:
                now = clock()
                if reader.waiting:  # (traces came while this step worked: not idle, whatever the clock says)
                    continue
                if reader.last_arrival is not None:
                    last_new = max(last_new, reader.last_arrival)
            if t_first is None:
                if cfg.start_timeout_s is not None and now - t_start >= cfg.start_timeout_s:
                    break
            elif cfg.until_idle_s is not None and now - last_new >= cfg.until_idle_s:
                break
            if not worked and not batches:
                if reader is not None:
                    reader.wait(poll_s)  # (woken as soon as traces come)
                else:
                    time.sleep(poll_s)
    except KeyboardInterrupt:  # Ctrl-C ends the survey: what came is finished and written (a second one aborts)
        interrupted = True
        log(f"interrupted: finishing with the {live.n_in if live else 0:,} traces received")
    finally:
        if reader is not None:
            reader.close()
        else:
            source.close()
    if live is None or live.n_in == 0:
        where = (getattr(getattr(source, "decoder", None), "where", None) or getattr(source, "path", None)
                 or "the source")
        waiting = getattr(source, "waiting_for_poses", 0)
        if waiting:
            raise GPR3DError(f"{where}: {waiting} traces came, but no poses for them in {source.tum.path}")
        why = (" before Ctrl-C" if interrupted else "" if cfg.start_timeout_s is None else
               f" in {cfg.start_timeout_s:g} s")
        raise GPR3DError(f"{where}: no traces arrived{why}")
    if getattr(source, "skipped", 0):
        log(f"{source.skipped:,} traces outside the poses' time span left out")
    t_last = clock()
    live.step(ended=True)
    t_end = clock()
    # the lag: from the newest trace's arrival to the end of the work on it. The work went on after it as long as
    # steps did some (a detector's backlog, say); a wait for the source after that (its idle time, or a stream
    # that went on with sensor messages only) is neither lag nor work
    done = max(worked_until, newest_arrival)
    lag = max(0.0, done - newest_arrival) + (t_end - t_last)
    busy = max(newest_arrival - t_first + lag, 1e-9)
    result = live.finish(source=str(getattr(source.header, "name", "")))
    lat = np.asarray(live.latencies) if live.latencies else np.zeros(1)
    summary = LiveSummary(n_traces=live.n_final, wall_s=busy, traces_per_s=live.n_final / busy,
                          lag_s=lag, latency_s={"median": float(np.median(lat)),
                                                "p99": float(np.percentile(lat, 99)), "max": float(lat.max())},
                          peak_tiles=live.peak_tiles, n_targets=len(live.targets),
                          n_detections=len(live.detections), final_volume=result is not None,
                          detect_thinned=live.detect_thinned, detect_skipped=live.detect_skipped,
                          busy_s={"migrate": live.migrate_s, "detect": live.detect_s, "refresh": live.refresh_s})
    if live.detect_thinned or live.detect_skipped:
        log(f"the detector fell behind: {live.detect_thinned} windows without overlap, {live.detect_skipped:,} traces "
            f"seen by no window (LiveConfig.detect_backlog: {cfg.detect_backlog:,} traces)")
    st = live.status()
    st["summary"] = asdict(summary)
    atomic_write_text(out / "live.json", json.dumps(st, indent=1))
    if live.detections:
        atomic_write_text(out / "detections.json", json.dumps(
            {"input": live.h.name, "channel": getattr(source, "channel", 0),
             "n_traces": live.n_in, "dt_s": live.h.dt_s,
             "detector": f"{getattr(detector, 'provenance', {}).get('name', 'gpr3d detector')} (live)",
             "score_threshold": cfg.score, "targets": live.detections},
            indent=1))
    summary.files = sorted(p.name for p in out.iterdir())
    return summary
