"""Sensors & Software pulseEKKO DT1 data with its HD header (and the .GPS sidecar).

The HD file is text (``KEY = value`` lines after a date line). The DT1 file holds,
per trace, a 128-byte header (float32 fields: 0 trace number, 1 position,
2 points per trace, 5 bytes per point, 23 time of day (s)) and the samples
(16-bit signed, or 32-bit when the trace header says 4 bytes per point).
The sample interval is ``TOTAL TIME WINDOW / NUMBER OF PTS/TRC``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError
from gpr3d.core.survey import Survey
from gpr3d.io._common import (
    check_file, data_and_header, finite_positive, gps_positions, header_count, nmea_degrees, sample_interval, sidecar,
    warn_fewer_traces, whole_traces,
)

__all__ = ["is_dt1", "read_dt1", "read_hd", "read_sns_gps"]

TRACE_HEADER_BYTES = 128
_UNITS_M = {"m": 1.0, "metres": 1.0, "meters": 1.0, "ft": 0.3048, "feet": 0.3048, "cm": 0.01, "in": 0.0254}


def read_hd(path) -> dict:
    """Parse an HD header into ``{KEY: value-string}`` plus ``"_date"`` and ``"_system"``."""
    p = check_file(path)
    raw = p.read_bytes()
    if b"\x00" in raw[:4096]:
        raise FormatError(p, "HD header holds binary bytes: not a pulseEKKO header or corrupt")
    text = raw.decode("latin-1")
    out: dict[str, str] = {}
    for line in text.splitlines():
        if "=" in line:
            k, v = line.split("=", 1)
            out[k.strip().upper()] = v.strip()
        elif re.match(r"^\s*\d{4}-\d{2}-\d{2}\s*$", line):
            out["_date"] = line.strip()
        elif "Data Collected with" in line:
            out["_system"] = line.strip()
    return out


def _hd_number(p, hd: dict, key: str, *, required: bool = True, default=None):
    if key not in hd:
        if required:
            raise FormatError(p, f"HD header lacks '{key}'")
        return default
    try:
        return float(hd[key].split()[0])
    except (ValueError, IndexError):
        raise FormatError(p, f"HD field '{key}' = {hd[key]!r} is not a number") from None


def read_sns_gps(path) -> dict:
    """Parse a pulseEKKO .GPS file: ``Trace #N at position X`` lines, each followed by a GGA sentence."""
    p = check_file(path)
    traces, lat, lon, alt = [], [], [], []
    current = None
    for line in p.read_bytes().decode("latin-1", errors="replace").splitlines():
        m = re.match(r"\s*Trace\s*#\s*(\d+)", line)
        if m:
            current = int(m.group(1))
            continue
        if current is not None and line.startswith("$") and line[3:6] == "GGA":
            parts = line.split("*")[0].split(",")
            try:
                if int(parts[6]) > 0:
                    traces.append(current)
                    lat.append(nmea_degrees(parts[2], parts[3]))
                    lon.append(nmea_degrees(parts[4], parts[5]))
                    alt.append(float(parts[9]) if parts[9] else 0.0)
            except (IndexError, ValueError):
                pass
            current = None
    return {"trace": np.asarray(traces, float), "lat": np.asarray(lat), "lon": np.asarray(lon), "alt": np.asarray(alt)}


def is_dt1(path) -> bool:
    p = Path(path)
    return p.suffix.lower() in (".dt1", ".hd") and sidecar(p, ".hd") is not None and sidecar(p, ".dt1") is not None


def read_dt1(path) -> list[Survey]:
    """Read a DT1/HD pair (give either file) as a one-element list of :class:`~gpr3d.core.survey.Survey`."""
    dt1, hd_path = data_and_header(path, (".dt1",), ".hd", "pulseEKKO")
    hd = read_hd(hd_path)
    n_hd = header_count(hd_path, "NUMBER OF TRACES", _hd_number(hd_path, hd, "NUMBER OF TRACES"), hi=10**8)
    npts = header_count(hd_path, "NUMBER OF PTS/TRC", _hd_number(hd_path, hd, "NUMBER OF PTS/TRC"), lo=2, hi=10**6)
    window_ns = finite_positive(hd_path, "TOTAL TIME WINDOW", _hd_number(hd_path, hd, "TOTAL TIME WINDOW"))
    dt_s = sample_interval(hd_path, window_ns * 1e-9 / npts, "TOTAL TIME WINDOW / NUMBER OF PTS/TRC")
    size = dt1.stat().st_size
    with open(dt1, "rb") as f:
        head = f.read(TRACE_HEADER_BYTES)
    if len(head) < TRACE_HEADER_BYTES:
        raise FormatError(dt1, f"file is {len(head)} bytes, shorter than one {TRACE_HEADER_BYTES}-byte trace header")
    first = np.frombuffer(head, dtype="<f4")
    bpp = int(first[5]) if math.isfinite(first[5]) and int(first[5]) in (2, 4) else 2
    trace_bytes = TRACE_HEADER_BYTES + npts * bpp
    n_file = whole_traces(dt1, size, trace_bytes, "trace")
    if n_file > n_hd:
        raise FormatError(dt1, f"file holds {n_file} traces but the HD header says {n_hd}: header and data disagree")
    partial = (size % trace_bytes) != 0  # already reported by whole_traces
    if n_file + int(partial) < n_hd:
        warn_fewer_traces(dt1, n_hd, n_file, "HD header")
    rec = np.dtype([("h", "<f4", (TRACE_HEADER_BYTES // 4,)), ("d", "<i2" if bpp == 2 else "<i4", (npts,))])
    arr = np.fromfile(dt1, dtype=rec, count=n_file)
    heads = arr["h"]
    pts_field = heads[:, 2]
    bad = np.nonzero(pts_field != npts)[0]
    if bad.size:
        i = int(bad[0])
        raise FormatError(dt1, f"trace {i} header says {pts_field[i]:g} points, HD says {npts}: corrupt or mismatched files")
    data = arr["d"].astype(np.float32)

    unit_name = hd.get("POSITION UNITS", "m").strip().lower()
    if unit_name not in _UNITS_M:
        raise FormatError(hd_path, f"unknown POSITION UNITS {unit_name!r}")
    unit = _UNITS_M[unit_name]
    dist = heads[:, 1].astype(float) * unit
    positions = None
    pos_source = None
    if np.all(np.isfinite(dist)) and np.ptp(dist) > 0:
        positions = np.zeros((n_file, 3))
        positions[:, 0] = dist
        pos_source = f"trace header positions ({unit_name}), along world x"
    gps_meta = None
    gps_file = sidecar(dt1, ".gps")
    if gps_file is not None:
        g = read_sns_gps(gps_file)
        gps_meta = {"file": gps_file.name, "fixes": int(g["trace"].size)}
        enu, origin = gps_positions(g["trace"], g["lat"], g["lon"], g["alt"], heads[:, 0])
        if enu is not None:
            positions = enu
            pos_source = "pulseEKKO .GPS (local ENU metres about origin)"
            gps_meta["origin_lat_lon_alt"] = list(origin)
    tod = heads[:, 23].astype(float)
    timestamps = tod if np.all(np.isfinite(tod)) and np.all(np.diff(tod) >= 0) and tod[-1] > 0 else None

    freq_mhz = _hd_number(hd_path, hd, "NOMINAL FREQUENCY", required=False)
    sep = _hd_number(hd_path, hd, "ANTENNA SEPARATION", required=False, default=0.0)
    tz_point = _hd_number(hd_path, hd, "TIMEZERO AT POINT", required=False)
    meta = {
        "format": "dt1",
        "path": str(dt1),
        "header_path": str(hd_path),
        "channel": 0,
        "n_channels": 1,
        "system": hd.get("_system"),
        "date": hd.get("_date"),
        "antenna": f"{freq_mhz:g} MHz pulseEKKO" if freq_mhz else "",
        "range_s": window_ns * 1e-9,
        "position_units": unit_name,
        "step_m": None if "STEP SIZE USED" not in hd else _hd_number(hd_path, hd, "STEP SIZE USED") * unit,
        "stacks": _hd_number(hd_path, hd, "NUMBER OF STACKS", required=False),
        "header_timezero_point": tz_point,
        "bytes_per_point": bpp,
        "positions_source": pos_source,
        "timestamps_source": "trace header time of day (s)" if timestamps is not None else None,
    }
    if gps_meta:
        meta["gps"] = gps_meta
    return [
        Survey(
            data=data,
            dt_s=dt_s,
            timestamps_s=timestamps,
            positions_xyz=positions,
            offset_m=(sep or 0.0) * unit,
            frequency_hz=None if not freq_mhz else freq_mhz * 1e6,
            metadata=meta,
        )
    ]
