"""Helpers shared by the format readers."""

from __future__ import annotations

import contextlib
import math
import os
import warnings
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError, TruncatedRecordingWarning


def check_file(path) -> Path:
    """The path as a Path; FormatError if it is missing, a folder, no regular file, unreadable, or empty."""
    import errno
    import stat

    p = Path(path)
    try:
        st = p.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise FormatError(p, "is a loop of symbolic links, not a file") from None
        if exc.errno == errno.EACCES:
            raise FormatError(p, "cannot be read: permission denied on the path") from None
        if p.is_symlink():
            raise FormatError(p, f"is a symbolic link to {os.readlink(p)}, which does not exist") from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            raise FormatError(p, "no such file") from None
        raise FormatError(p, f"cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise FormatError(p, "is a folder, not a file")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                else "a device")
        raise FormatError(p, f"is {kind}, not a regular file: radar files are read from disk")
    if st.st_size == 0:
        raise FormatError(p, "file is empty")
    if not os.access(p, os.R_OK):
        raise FormatError(p, "cannot be read: permission denied")
    return p


def sidecar(path: Path, *suffixes: str) -> Path | None:
    """The first existing file with the same stem and one of ``suffixes`` (any letter case)."""
    for suf in suffixes:
        for cand in (suf.lower(), suf.upper()):
            q = path.with_suffix(cand)
            if q.exists():
                return q
    # case-insensitive scan (e.g. 'File.Dzg')
    try:
        names = {n.lower(): n for n in os.listdir(path.parent)}
    except OSError:
        return None
    for suf in suffixes:
        hit = names.get((path.stem + suf).lower())
        if hit:
            return path.parent / hit
    return None


def whole_traces(path, n_bytes: int, trace_bytes: int, what: str = "trace") -> int:
    """Number of complete traces in ``n_bytes``; warns if the recording ends mid-trace."""
    if trace_bytes <= 0:
        raise FormatError(path, f"{what} size {trace_bytes} bytes is impossible")
    n, rest = divmod(n_bytes, trace_bytes)
    if n == 0:
        raise FormatError(path, f"holds no complete {what} ({n_bytes} data bytes, one {what} needs {trace_bytes})")
    if rest:
        warnings.warn(
            f"{Path(path).name}: recording ends mid-{what}; dropped 1 partial {what} ({rest} bytes), kept {n}",
            TruncatedRecordingWarning,
            stacklevel=3,
        )
    return n


def finite_positive(path, name: str, value, *, allow_zero: bool = False) -> float:
    """``value`` as float; FormatError if it is not finite and positive."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise FormatError(path, f"header field {name} = {value!r} is not a number") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise FormatError(path, f"header field {name} = {v!r} is not a positive number")
    return v


#: the sample intervals a radar (or an FDTD model of one) produces: 0.01 ps (a gprMax grid of 0.01 mm cells) to
#: 1 us (1 MHz sampling, below the lowest GPR antenna's band)
SAMPLE_INTERVAL_RANGE_S = (1e-14, 1e-6)


def header_count(path, name: str, value, *, lo: int = 1, hi: int = 10**9) -> int:
    """A header's count field (traces, samples, channels) as int; FormatError unless a whole number in lo..hi."""
    try:
        v = float(value)
    except (TypeError, ValueError):  # (an array's repr spans lines: one line, cut short)
        shown = " ".join(repr(value).split())
        raise FormatError(path, f"header field {name} = {shown[:60]} is not a number") from None
    if not math.isfinite(v) or v != math.floor(v):
        shown = repr(value) if isinstance(value, str) else f"{v:.10g}"
        raise FormatError(path, f"header field {name} = {shown} is not a whole number")
    if not lo <= v <= hi:
        raise FormatError(path, f"header field {name} = {v:.10g} is implausible (expected {lo}..{hi})")
    return int(v)


def sample_interval(path, dt_s: float, source: str) -> float:
    """``dt_s`` if it is a sample interval a radar produces, else FormatError naming the header field(s) ``source``."""
    lo, hi = SAMPLE_INTERVAL_RANGE_S
    if not (math.isfinite(dt_s) and lo <= dt_s <= hi):
        raise FormatError(path, f"the sample interval from {source} is {dt_s:.3g} s, which no radar records "
                                f"(expected {lo:g}..{hi:g} s)")
    return float(dt_s)


def check_finite(path, data: np.ndarray) -> None:
    bad = np.count_nonzero(~np.isfinite(data))
    if bad:
        raise FormatError(path, f"{bad} samples are NaN or infinite")


def nmea_degrees(value: str, hemisphere: str) -> float:
    """Degrees from NMEA ``ddmm.mmmm`` / ``dddmm.mmmm`` and a hemisphere letter."""
    v = float(value)
    deg = math.floor(v / 100.0)
    out = deg + (v - 100.0 * deg) / 60.0
    return -out if hemisphere.strip().upper() in ("S", "W") else out


def local_metres(lat_deg, lon_deg, alt_m, origin=None):
    """East-north-up metres of geographic points about ``origin`` (lat, lon, alt).

    A local tangent-plane (equirectangular) approximation on the WGS-84
    ellipsoid's radii of curvature; good to centimetres over a few km.
    """
    lat = np.asarray(lat_deg, float)
    lon = np.asarray(lon_deg, float)
    alt = np.asarray(alt_m, float)
    if origin is None:
        origin = (float(lat[0]), float(lon[0]), float(alt[0]))
    lat0, lon0, alt0 = origin
    a, e2 = 6378137.0, 6.69437999014e-3
    s = math.sin(math.radians(lat0))
    n_radius = a / math.sqrt(1 - e2 * s * s)
    m_radius = a * (1 - e2) / (1 - e2 * s * s) ** 1.5
    east = np.radians(lon - lon0) * n_radius * math.cos(math.radians(lat0))
    north = np.radians(lat - lat0) * m_radius
    return np.stack([east, north, alt - alt0], axis=1), origin


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: files already walked by :func:`check_hdf5_survives` in this process: (path, size, mtime) -> True
_HDF5_SURVIVED: dict = {}


def _walk_hdf5(path: str, max_bytes: int) -> None:
    """Read every attribute and every dataset (up to ``max_bytes`` each) of an HDF5 file: what readers will do."""
    import h5py

    with h5py.File(path, "r") as f:
        dict(f.attrs)

        def visit(_name, obj):
            dict(obj.attrs)
            if isinstance(obj, h5py.Dataset) and obj.size * obj.dtype.itemsize <= max_bytes:
                obj[()]

        f.visititems(visit)


#: the pre-check's time: this much for the library to walk a file's structure, plus its data at the slowest disk
#: speed a reader should wait for (a walk that takes longer is the library caught in a loop a damaged file set)
HDF5_WALK_BASE_S, HDF5_WALK_BYTES_PER_S = 10.0, 10e6


def check_hdf5_survives(path, *, max_bytes: int = 256 * 2**20, timeout_s: float | None = None) -> None:
    """Walk an HDF5 file in a forked child before this process opens it, and raise :class:`FormatError` if the
    HDF5 library crashes there (a corrupt file can make libhdf5 segfault, which no ``except`` catches) or does not
    finish (a damaged file can send it round a loop for ever, where no signal reaches Python either).

    Errors the child meets are left for the reader (it reports them by name). The child is given ``timeout_s``
    (default :data:`HDF5_WALK_BASE_S` plus the data it reads at :data:`HDF5_WALK_BYTES_PER_S`); it is ended when the
    time is up, and whenever the wait is cut short (an interrupt, an alarm), so none is left behind. Each file
    (path, size, mtime) is walked once per process; not on systems without ``fork``, nor with
    ``GPR3D_HDF5_PRECHECK=0``."""
    if not hasattr(os, "fork") or os.environ.get("GPR3D_HDF5_PRECHECK", "1") == "0":
        return
    p = Path(path)
    try:
        st = p.stat()
        with open(p, "rb") as fh:
            if fh.read(8) != HDF5_SIGNATURE:
                return
    except OSError:
        return
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    if key in _HDF5_SURVIVED:
        return
    import signal
    import time

    if timeout_s is None:
        timeout_s = HDF5_WALK_BASE_S + min(st.st_size, max_bytes) / HDF5_WALK_BYTES_PER_S
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # the child: walk, then leave without running any of the parent's exit handlers
        try:
            import faulthandler

            faulthandler.disable()  # a crash here is the parent's to report, in one line: no dump from the child
            os.dup2(os.open(os.devnull, os.O_WRONLY), 2)
            _walk_hdf5(str(p), max_bytes)
        except BaseException:  # noqa: BLE001 - errors are the reader's to report
            pass
        os._exit(0)
    deadline = time.monotonic() + timeout_s
    reaped = False
    try:
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                reaped = True
                break
            if time.monotonic() > deadline:
                raise FormatError(p, f"HDF5 content is corrupt: the HDF5 library did not finish reading its "
                                     f"structure within {timeout_s:.0f} s (a damaged file can loop it for ever)")
            time.sleep(0.002)
    finally:
        # the time is up, or the wait was cut short: end the child, leave no process behind (only ever from the
        # parent, and only its own child: never a process group)
        if not reaped and os.getpid() == parent and pid > 0:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        name = signal.Signals(sig).name if sig in signal.Signals._value2member_map_ else str(sig)
        raise FormatError(p, f"HDF5 content is corrupt: the HDF5 library crashed reading it ({name})")
    _HDF5_SURVIVED[key] = True


@contextlib.contextmanager
def hdf5_errors(path):
    """Turn the low-level errors h5py raises on damaged files into one FormatError naming the file.

    A corrupt HDF5 file fails deep inside the library (OSError, RuntimeError,
    KeyError, ValueError, TypeError...); gpr3d's own errors pass through unchanged.
    """
    from gpr3d.core.errors import GPR3DError

    try:
        yield
    except GPR3DError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError) as exc:
        detail = str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__
        raise FormatError(path, f"HDF5 content is corrupt or truncated ({detail})") from None


def data_and_header(path, data_suffixes: tuple[str, ...], header_suffix: str, vendor: str):
    """Resolve a data/header file pair from either file: ``(data_path, header_path)`` or FormatError."""
    p = Path(path)
    data = p if p.suffix.lower() in data_suffixes else next(
        (q for q in (sidecar(p, s) for s in data_suffixes) if q is not None), None)
    header = p if p.suffix.lower() == header_suffix else sidecar(p, header_suffix)
    names = "/".join(data_suffixes)
    if data is None:
        raise FormatError(p, f"no {names} data file beside the header")
    if header is None:
        raise FormatError(p, f"no {header_suffix} header beside the data ({vendor} needs both)")
    return check_file(data), check_file(header)


def warn_fewer_traces(path, header_count: int, file_count: int, field: str) -> None:
    """Warn that the header promises more traces than the (truncated) file holds."""
    warnings.warn(f"{Path(path).name}: {field} says {header_count} traces, file holds {file_count}; "
                  f"reading {file_count}", TruncatedRecordingWarning, stacklevel=3)


def gps_positions(fix_index, lat, lon, alt, trace_index):
    """Per-trace local ENU metres from GPS fixes at (fractional) trace indices.

    Returns ``(positions (n, 3), origin (lat, lon, alt))``, or ``(None, None)`` when
    fewer than two fixes with increasing indices exist.
    """
    fix_index = np.asarray(fix_index, dtype=float)
    if fix_index.size < 2 or np.any(np.diff(fix_index) <= 0):
        return None, None
    ti = np.asarray(trace_index, dtype=float)
    return local_metres(np.interp(ti, fix_index, lat), np.interp(ti, fix_index, lon), np.interp(ti, fix_index, alt))
