"""Replay a recording as a radar would deliver it (``gpr3d replay``): for live mode's tests and benchmarks.

- to ``tcp://HOST:PORT``: a server there sends the :mod:`gpr3d.io.stream` format (header, then each trace with its
  pose) to the first client that connects, at the given rate, then the end mark;
- to a ``.DZT`` or ``.DT1`` file: a DZT recording's header (a pulseEKKO recording's HD header, beside it), then
  its traces appended at the given rate (as the radar writes them), and with ``poses_out`` its poses appended to a
  TUM file in step.

``loops`` plays the recording several times, each pass moved ``loop_shift_m`` further along x (a long survey from a
short one: the cart never comes back). With ``sensors`` (:func:`read_sensors`: an IMU record, camera poses, wheel
readings) the stream carries them too, every message at its own time among the traces' (on the IMU clock), for
``gpr3d live --fuse``.
"""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path

import numpy as np

from gpr3d.core.errors import GPR3DError
from gpr3d.io.stream import (END, StreamHeader, encode_camera_pose, encode_header, encode_imu, encode_trace,
                             encode_wheel)

__all__ = ["pace", "pace_at", "read_sensors", "replay_to_file", "replay_to_tcp"]


def pace(n: int, rate: float, *, batch_s: float = 0.01, clock=time.monotonic, sleep=time.sleep):
    """``(a, b)`` ranges of ``n`` items, each handed out once its last item is due at ``rate`` items per second
    (in steps of about ``batch_s``; a consumer that falls behind gets larger ranges, never a drift)."""
    if not (rate > 0 and math.isfinite(rate)):
        raise GPR3DError(f"the replay rate must be a positive number of traces per second, got {rate!r}")
    yield from pace_at(np.arange(n) / rate, batch_s=batch_s, clock=clock, sleep=sleep)  # item i is due at i / rate


def pace_at(due_s, *, batch_s: float = 0.01, clock=time.monotonic, sleep=time.sleep):
    """:func:`pace` for items due at the given times (s from the start, not decreasing)."""
    due_s = np.asarray(due_s, float)
    n = due_s.size
    t0 = clock()
    a = 0
    while a < n:
        elapsed = clock() - t0
        due = int(np.searchsorted(due_s, elapsed, side="right"))
        if due <= a:
            sleep(max(0.0, min(batch_s, due_s[a] - elapsed)))
            continue
        yield a, due
        a = due


def read_sensors(imu, odometry=None, wheel=None) -> dict:
    """A cart's sensor records as a trace stream carries them (:func:`replay_to_tcp`'s ``sensors``).

    Parameters
    ----------
    imu : str or Path
        IMU samples (CSV: ``t, ax, ay, az, gx, gy, gz``; s, m/s^2, rad/s), as ``gpr3d pose fuse`` reads them.
    odometry : str or Path, optional
        The visual odometry's camera poses (TUM, EuRoC or CSV).
    wheel : str or Path, optional
        Survey wheel readings (CSV: ``t, distance``).

    Returns
    -------
    dict
        ``"imu"``: ``(k, 7)`` rows ``t ax ay az gx gy gz``; with ``odometry``, ``"odometry"``: ``(k, 8)`` rows
        ``t x y z qw qx qy qz``; with ``wheel``, ``"wheel"``: ``(k, 2)`` rows ``t distance``.

    Raises
    ------
    GPR3DError
        A file that cannot be read as its kind, in one line naming it.
    """
    from gpr3d.io.inertial import read_imu_csv, read_wheel_csv
    from gpr3d.io.trajectory import read_trajectory

    m = read_imu_csv(imu)
    out = {"imu": np.c_[m.t_s, m.accel, m.gyro]}
    if odometry is not None:
        tr = read_trajectory(odometry)
        out["odometry"] = np.c_[tr.timestamps_s, tr.positions_xyz, tr.orientations_quat_wxyz]
    if wheel is not None:
        t, d = read_wheel_csv(wheel)
        out["wheel"] = np.c_[t, d]
    return out


_ENCODERS = {"imu": lambda r: encode_imu(r[0], r[1:4], r[4:7]), "odometry": lambda r: encode_camera_pose(r[0], r[1:8]),
             "wheel": lambda r: encode_wheel(r[0], r[1])}


def _serve_with_sensors(conn, survey, poses, sensors: dict, speed: float, log) -> tuple[int, bool]:
    """Send the traces and the sensor messages in time order, each when due at ``speed`` times the record's pace:
    ``(traces sent, whether all went: the client stayed)``."""
    times = np.asarray(survey.timestamps_s, float)
    kinds = [("trace", times)] + [(k, np.asarray(v, float)[:, 0]) for k, v in sensors.items()]
    when = np.concatenate([t for _, t in kinds])
    kind = np.concatenate([np.full(t.size, j) for j, (_, t) in enumerate(kinds)])
    row = np.concatenate([np.arange(t.size) for _, t in kinds])
    order = np.argsort(when, kind="stable")
    when, kind, row = when[order], kind[order], row[order]
    sent = 0
    for a, b in pace_at((when - when[0]) / speed):
        buf = bytearray()
        for j, r in zip(kind[a:b], row[a:b]):
            if j == 0:
                buf += encode_trace(r, times[r], poses[r], survey.data[r])
            else:
                name = kinds[j][0]
                buf += _ENCODERS[name](sensors[name][r])
        try:
            conn.sendall(buf)
        except (BrokenPipeError, ConnectionResetError):
            if log:
                log(f"the client left after {sent} traces")
            return sent, False
        sent += int(np.count_nonzero(kind[a:b] == 0))
    return sent, True


def _poses(survey) -> np.ndarray:
    if survey.positions_xyz is None:
        raise GPR3DError("the recording has no antenna poses to send: give --poses (a TUM file, one per trace)")
    q = survey.orientations_quat_wxyz
    if q is None:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (survey.n_traces, 1))
    q = np.asarray(q, float) / np.linalg.norm(q, axis=1, keepdims=True)
    return np.column_stack([survey.positions_xyz, q])


def replay_to_tcp(survey, port: int, *, host: str = "127.0.0.1", rate: float, loops: int = 1,
                  loop_shift_m: float = 0.0, accept_s: float = 30.0, on_listen=None, log=None,
                  sensors: dict | None = None) -> int:
    """Serve ``survey`` with its poses to the first client that connects, at ``rate`` traces per second.

    Parameters
    ----------
    survey : Survey
        With ``positions_xyz`` (and orientations; none: the antenna along world x).
    port : int
        The port to listen on (0: any free one; ``on_listen`` is told which).
    host : str
        The address to listen on.
    rate : float
        Traces per second.
    loops : int
        How many times the recording is played.
    loop_shift_m : float
        How much further along x each pass lies (m).
    accept_s : float
        How long to wait for a client (s).
    on_listen : callable, optional
        Called with the port once the server listens.
    log : callable, optional
        A line when the client leaves early.
    sensors : dict, optional
        Sensor records to send beside the traces (:func:`read_sensors`; ``"imu"`` at least): every message at its
        time among the traces' (the survey's ``timestamps_s``, on the IMU clock), the whole paced so that the
        traces come at ``rate`` on average; the traces' poses are sent where the survey has them (else NaN: to be
        fused). One pass only.

    Returns
    -------
    int
        The traces sent.

    Raises
    ------
    GPR3DError
        A survey without poses (and no ``sensors``), a rate that is no positive number, no client in
        ``accept_s``; with ``sensors``: traces without times, no IMU record, ``loops``.
    """
    n = survey.n_traces
    speed = None
    if sensors is not None:
        if "imu" not in sensors:
            raise GPR3DError("the sensors sent beside the traces must include the IMU's")
        if loops != 1:
            raise GPR3DError("a replay with sensor records plays once (no --loops)")
        t = survey.timestamps_s
        if t is None or n < 2 or not np.all(np.diff(t) >= 0) or t[-1] <= t[0]:
            raise GPR3DError("the recording's traces carry no increasing times to place them among the sensor "
                             "records (on the IMU clock)")
        if not (rate > 0 and math.isfinite(rate)):
            raise GPR3DError(f"the replay rate must be a positive number of traces per second, got {rate!r}")
        speed = rate * (t[-1] - t[0]) / (n - 1)
        poses = _poses(survey) if survey.positions_xyz is not None else np.full((n, 7), np.nan)
        imu_t = np.asarray(sensors["imu"], float)[:, 0]
        rate_hz = float(1.0 / np.median(np.diff(imu_t))) if imu_t.size > 1 else None
    else:
        poses = _poses(survey)
        rate_hz = None
    header = StreamHeader(n_samples=survey.n_samples, dt_s=survey.dt_s, frequency_hz=survey.frequency_hz,
                          offset_m=survey.offset_m, eps_r=survey.eps_r,
                          name=str(survey.metadata.get("path", "replay")),
                          sensors=tuple(sensors) if sensors else (), imu_rate_hz=rate_hz)
    try:
        srv = socket.create_server((host, port))
    except OSError as exc:
        raise GPR3DError(f"tcp://{host}:{port}: cannot listen there ({exc.strerror or exc})") from None
    srv.settimeout(accept_s)
    if on_listen is not None:
        on_listen(srv.getsockname()[1])
    try:
        try:
            conn, _ = srv.accept()
        except socket.timeout:
            raise GPR3DError(f"tcp://{host}:{srv.getsockname()[1]}: no client connected in {accept_s:g} s") from None
        with conn:
            conn.sendall(encode_header(header))
            if sensors is not None:
                sent, whole = _serve_with_sensors(conn, survey, poses, sensors, speed, log)
                if whole:
                    _end(conn)
                return sent
            sent = 0
            t_rel = np.arange(n * loops) / rate
            for a, b in pace(n * loops, rate):
                buf = bytearray()
                for i in range(a, b):
                    k, loop = i % n, i // n
                    p = poses[k].copy()
                    p[0] += loop * loop_shift_m
                    buf += encode_trace(i, float(t_rel[i]), p, survey.data[k])
                try:
                    conn.sendall(buf)
                except (BrokenPipeError, ConnectionResetError):
                    if log:
                        log(f"the client left after {sent} traces")
                    return sent
                sent = b
            _end(conn)
            return sent
    finally:
        srv.close()


def _end(conn) -> None:
    conn.sendall(END)
    try:  # let the client read to the end before the connection closes
        conn.shutdown(socket.SHUT_WR)
        conn.settimeout(5.0)
        while conn.recv(4096):
            pass
    except OSError:
        pass


def _file_layout(src: Path) -> tuple[int, int, int]:
    """``(header bytes, trace bytes, whole traces)`` of a DZT or DT1 recording; a one-line FormatError for
    anything else."""
    from gpr3d.core.errors import FormatError

    kind = src.suffix.lower()
    if kind == ".dzt":
        from gpr3d.io.dzt import read_dzt_header

        hdr = read_dzt_header(src)
        tb = hdr["n_samples"] * hdr["n_channels"] * hdr["bits"] // 8
        return hdr["data_offset"], tb, (hdr["file_bytes"] - hdr["data_offset"]) // tb
    if kind == ".dt1":
        from gpr3d.io.dt1 import TRACE_HEADER_BYTES
        from gpr3d.io.stream import dt1_layout

        layout = dt1_layout(src)
        if layout is None:
            raise FormatError(src, "no such file, or shorter than one trace header: not a pulseEKKO DT1")
        tb = TRACE_HEADER_BYTES + layout[0] * layout[1]
        return 0, tb, src.stat().st_size // tb
    raise FormatError(src, "replaying into a file takes a DZT or DT1 recording")


def replay_to_file(recording, out, *, rate: float, poses=None, poses_out=None) -> int:
    """Grow a DZT or pulseEKKO DT1 file as a radar would: ``recording``'s header (a DT1's HD header, copied beside
    ``out`` first), then its traces at ``rate`` per second.

    Parameters
    ----------
    recording : str or Path
        A DZT or DT1 file.
    out : str or Path
        The file written (flushed after every batch of traces), of the recording's kind.
    rate : float
        Traces per second.
    poses : str or Path, optional
        A TUM file, one pose per trace: its lines are appended to ``poses_out`` in step with the traces.
    poses_out : str or Path, optional
        Where the poses grow (needed with ``poses``).

    Returns
    -------
    int
        The traces written.

    Raises
    ------
    GPR3DError
        Poses that do not match the traces, no ``poses_out``, ``out`` being the recording or of another kind, or a
        rate that is no positive number.
    FormatError
        A recording that is no DZT or DT1.
    """
    src = Path(recording)
    if Path(out).suffix.lower() != src.suffix.lower():
        raise GPR3DError(f"--to {out}: a {src.suffix.upper().lstrip('.')} recording grows into a "
                         f"{src.suffix.upper()} file")
    head, tb, n = _file_layout(src)
    lines = None
    if poses is not None:
        lines = [ln for ln in Path(poses).read_text().splitlines() if ln.strip() and not ln.startswith("#")]
        if len(lines) != n:
            raise GPR3DError(f"{poses} holds {len(lines)} poses but {src} has {n} traces (one pose per trace)")
        if poses_out is None:
            raise GPR3DError("give where the poses go (--poses-out) beside --poses")
    out = Path(out)
    if out.resolve() == src.resolve():
        raise GPR3DError(f"--to {out} is the recording itself")
    if src.suffix.lower() == ".dt1":
        from gpr3d.io._common import sidecar

        hd = sidecar(src, ".hd")
        if hd is not None:
            Path(out).with_suffix(hd.suffix).write_bytes(hd.read_bytes())
    pf = open(poses_out, "w") if lines is not None else None
    try:
        with open(src, "rb") as fin, open(out, "wb") as fout:
            fout.write(fin.read(head))
            fout.flush()
            for a, b in pace(n, rate):
                fout.write(fin.read((b - a) * tb))
                fout.flush()
                if pf is not None:
                    pf.write("".join(ln + "\n" for ln in lines[a:b]))
                    pf.flush()
    finally:
        if pf is not None:
            pf.close()
    return int(n)

