"""Replay a recording as a radar would deliver it (``gpr3d replay``): for live mode's tests and benchmarks.

- to ``tcp://HOST:PORT``: a server there sends the :mod:`gpr3d.io.stream` format (header, then each trace with its
  pose) to the first client that connects, at the given rate, then the end mark;
- to a ``.DZT`` file: a DZT recording's header, then its traces appended at the given rate (as the radar writes
  them), and with ``poses_out`` its poses appended to a TUM file in step.

``loops`` plays the recording several times, each pass moved ``loop_shift_m`` further along x (a long survey from a
short one: the cart never comes back).
"""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path

import numpy as np

from gpr3d.core.errors import GPR3DError
from gpr3d.io.stream import END, StreamHeader, encode_header, encode_trace

__all__ = ["pace", "replay_to_dzt", "replay_to_tcp"]


def pace(n: int, rate: float, *, batch_s: float = 0.01, clock=time.monotonic, sleep=time.sleep):
    """``(a, b)`` ranges of ``n`` items, each handed out once its last item is due at ``rate`` items per second
    (in steps of about ``batch_s``; a consumer that falls behind gets larger ranges, never a drift)."""
    if not (rate > 0 and math.isfinite(rate)):
        raise GPR3DError(f"the replay rate must be a positive number of traces per second, got {rate!r}")
    t0 = clock()
    a = 0
    while a < n:
        elapsed = clock() - t0
        due = min(n, int(elapsed * rate) + 1)  # item i is due at i / rate
        if due <= a:
            sleep(max(0.0, min(batch_s, a / rate - elapsed)))
            continue
        yield a, due
        a = due


def _poses(survey) -> np.ndarray:
    if survey.positions_xyz is None:
        raise GPR3DError("the recording has no antenna poses to send: give --poses (a TUM file, one per trace)")
    q = survey.orientations_quat_wxyz
    if q is None:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (survey.n_traces, 1))
    q = np.asarray(q, float) / np.linalg.norm(q, axis=1, keepdims=True)
    return np.column_stack([survey.positions_xyz, q])


def replay_to_tcp(survey, port: int, *, host: str = "127.0.0.1", rate: float, loops: int = 1,
                  loop_shift_m: float = 0.0, accept_s: float = 30.0, on_listen=None, log=None) -> int:
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

    Returns
    -------
    int
        The traces sent.

    Raises
    ------
    GPR3DError
        A survey without poses, a rate that is no positive number, or no client in ``accept_s``.
    """
    poses = _poses(survey)
    n = survey.n_traces
    header = StreamHeader(n_samples=survey.n_samples, dt_s=survey.dt_s, frequency_hz=survey.frequency_hz,
                          offset_m=survey.offset_m, eps_r=survey.eps_r,
                          name=str(survey.metadata.get("path", "replay")))
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
            conn.sendall(END)
            try:  # let the client read to the end before the connection closes
                conn.shutdown(socket.SHUT_WR)
                conn.settimeout(5.0)
                while conn.recv(4096):
                    pass
            except OSError:
                pass
            return sent
    finally:
        srv.close()


def replay_to_dzt(recording, out, *, rate: float, poses=None, poses_out=None) -> int:
    """Grow a DZT file as a radar would: ``recording``'s header, then its traces at ``rate`` per second.

    Parameters
    ----------
    recording : str or Path
        A DZT file.
    out : str or Path
        The DZT file written (flushed after every batch of traces).
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
        Poses that do not match the traces, no ``poses_out``, ``out`` being the recording, or a rate that is no
        positive number.
    FormatError
        A recording that is no DZT.
    """
    from gpr3d.io.dzt import read_dzt_header

    src = Path(recording)
    hdr = read_dzt_header(src)
    tb = hdr["n_samples"] * hdr["n_channels"] * hdr["bits"] // 8
    n = (hdr["file_bytes"] - hdr["data_offset"]) // tb
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
    pf = open(poses_out, "w") if lines is not None else None
    try:
        with open(src, "rb") as fin, open(out, "wb") as fout:
            fout.write(fin.read(hdr["data_offset"]))
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

