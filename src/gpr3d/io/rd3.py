"""MALA RAMAC/ProEx data: ``.rd3`` (16-bit) or ``.rd7`` (32-bit) samples, ``.rad`` header, ``.cor`` GPS.

The RAD header is text (``KEY:value``). Samples are stored trace after trace,
little-endian signed integers. The sample interval is ``1 / FREQUENCY`` (the
sampling frequency, MHz). ``TIMEWINDOW`` is kept in the metadata as written:
in the files we checked it is twice ``SAMPLES / FREQUENCY``, and the spectrum
of the data peaks at the antenna's nominal frequency only with ``1/FREQUENCY``
(493 MHz for a 500 MHz antenna, against 246 MHz with ``TIMEWINDOW/SAMPLES``).
When ``FREQUENCY`` is missing, ``TIMEWINDOW / SAMPLES`` is used.
The COR file has one line per GPS fix: trace, date, time, latitude, N/S,
longitude, E/W, altitude, unit, accuracy (decimal degrees).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError
from gpr3d.core.survey import Survey
from gpr3d.io._common import (
    check_file, data_and_header, finite_positive, gps_positions, header_count, sample_interval, sidecar,
    warn_fewer_traces, whole_traces,
)

__all__ = ["is_rd3", "read_rd3", "read_rad", "read_cor"]


def read_rad(path) -> dict:
    """Parse a RAD header into ``{KEY: value-string}``."""
    p = check_file(path)
    raw = p.read_bytes()
    if b"\x00" in raw[:4096]:
        raise FormatError(p, "RAD header holds binary bytes: not a MALA header or corrupt")
    out = {}
    for line in raw.decode("latin-1").splitlines():
        if ":" in line:
            k, v = line.split(":", 1)
            out[k.strip().upper()] = v.strip()
    return out


def _num(p, rad: dict, key: str, *, required: bool = True, default=None) -> float | None:
    if key not in rad:
        if required:
            raise FormatError(p, f"RAD header lacks '{key}'")
        return default
    try:
        return float(rad[key])
    except ValueError:
        raise FormatError(p, f"RAD field '{key}' = {rad[key]!r} is not a number") from None


def read_cor(path) -> dict:
    """GPS fixes from a COR file: ``{"trace", "lat", "lon", "alt"}`` arrays (bad lines skipped)."""
    p = check_file(path)
    tr, lat, lon, alt = [], [], [], []
    for line in p.read_bytes().decode("latin-1", errors="replace").splitlines():
        parts = line.split()
        if len(parts) < 8:
            continue
        try:
            t = int(parts[0])
            la = float(parts[3]) * (-1 if parts[4].upper() == "S" else 1)
            lo = float(parts[5]) * (-1 if parts[6].upper() == "W" else 1)
            al = float(parts[7])
        except ValueError:
            continue
        tr.append(t), lat.append(la), lon.append(lo), alt.append(al)
    return {"trace": np.asarray(tr, float), "lat": np.asarray(lat), "lon": np.asarray(lon), "alt": np.asarray(alt)}


def is_rd3(path) -> bool:
    p = Path(path)
    return p.suffix.lower() in (".rd3", ".rd7", ".rad") and sidecar(p, ".rad") is not None and (
        sidecar(p, ".rd3") is not None or sidecar(p, ".rd7") is not None
    )


def read_rd3(path) -> list[Survey]:
    """Read a MALA ``.rd3``/``.rd7`` + ``.rad`` pair (give any of them) as a one-element list."""
    data_path, rad_path = data_and_header(path, (".rd3", ".rd7"), ".rad", "MALA")
    rad = read_rad(rad_path)
    nsamp = header_count(rad_path, "SAMPLES", _num(rad_path, rad, "SAMPLES"), lo=2, hi=10**6)
    fs_mhz = _num(rad_path, rad, "FREQUENCY", required=False)
    window_hd = _num(rad_path, rad, "TIMEWINDOW", required=fs_mhz is None)
    if fs_mhz is not None:
        dt = 1e-6 / finite_positive(rad_path, "FREQUENCY", fs_mhz)
    else:
        dt = finite_positive(rad_path, "TIMEWINDOW", window_hd) * 1e-9 / nsamp
    dt = sample_interval(rad_path, dt, "FREQUENCY" if fs_mhz is not None else "TIMEWINDOW / SAMPLES")
    nbytes = 2 if data_path.suffix.lower() == ".rd3" else 4
    size = data_path.stat().st_size
    last = _num(rad_path, rad, "LAST TRACE", required=False)
    if last is not None:
        last = header_count(rad_path, "LAST TRACE", last, hi=10**8)
        # no whole number of SAMPLES-long traces, but exactly LAST TRACE traces of another length: SAMPLES is
        # wrong, and reading would shear every trace (a file cut short at a trace's end still reads)
        per, rest = divmod(size, last * nbytes)
        if size % (nsamp * nbytes) and rest == 0 and per >= 2:
            raise FormatError(rad_path, f"SAMPLES = {nsamp} does not fit {data_path.name} ({size:,} bytes: no whole "
                                        f"number of {nsamp}-sample traces, but {last} traces (LAST TRACE) of {per} "
                                        "samples): the header or the data is wrong")
    n = whole_traces(data_path, size, nsamp * nbytes, "trace")
    if last is not None and last != n:
        if last < n:
            raise FormatError(data_path, f"file holds {n} traces but LAST TRACE says {last}: header and data disagree")
        warn_fewer_traces(data_path, last, n, "LAST TRACE")
    data = np.fromfile(data_path, dtype="<i2" if nbytes == 2 else "<i4", count=n * nsamp).reshape(n, nsamp)
    data = data.astype(np.float32)

    ant = rad.get("ANTENNAS", "")
    m = re.search(r"(\d+(?:\.\d+)?)\s*(?:MHz)?", ant)
    freq_hz = float(m.group(1)) * 1e6 if m else None
    interval = _num(rad_path, rad, "DISTANCE INTERVAL", required=False, default=0.0) or 0.0
    t_interval = _num(rad_path, rad, "TIME INTERVAL", required=False, default=0.0) or 0.0
    positions = None
    pos_source = None
    timestamps = np.arange(n) * t_interval if t_interval > 0 else None
    if interval > 0:
        positions = np.zeros((n, 3))
        positions[:, 0] = np.arange(n) * interval
        pos_source = "header DISTANCE INTERVAL, along world x"
    cor_path = sidecar(data_path, ".cor")
    gps_meta = None
    if cor_path is not None:
        g = read_cor(cor_path)
        gps_meta = {"file": cor_path.name, "fixes": int(g["trace"].size)}
        # COR traces count from 1
        enu, origin = gps_positions(g["trace"], g["lat"], g["lon"], g["alt"], np.arange(1, n + 1))
        if enu is not None:
            positions = enu
            pos_source = "COR GPS (local ENU metres about origin)"
            gps_meta["origin_lat_lon_alt"] = list(origin)
    meta = {
        "format": "rd3",
        "path": str(data_path),
        "header_path": str(rad_path),
        "channel": 0,
        "n_channels": 1,
        "antenna": ant,
        "range_s": nsamp * dt,
        "header_timewindow_s": None if window_hd is None else window_hd * 1e-9,
        "sampling_frequency_hz": None if fs_mhz is None else fs_mhz * 1e6,
        "stacks": _num(rad_path, rad, "STACKS", required=False),
        "positions_source": pos_source,
    }
    if gps_meta:
        meta["gps"] = gps_meta
    return [
        Survey(
            data=data,
            dt_s=dt,
            timestamps_s=timestamps,
            positions_xyz=positions,
            offset_m=_num(rad_path, rad, "ANTENNA SEPARATION", required=False, default=0.0) or 0.0,
            frequency_hz=freq_hz,
            metadata=meta,
        )
    ]
