"""GSSI DZT files (SIR-3000/4000/20/30, UtilityScan, StructureScan), with the DZG GPS sidecar.

Layout (little-endian): one 1024-byte header per channel, then traces ("scans"),
each holding ``n_samples`` samples of every channel in turn. Samples are unsigned
8- or 16-bit integers about a binary zero (128, 32768) or signed 32-bit integers.
The data start at ``1024 * rh_data`` when ``rh_data < 1024``, else at
``1024 * n_channels`` (SIR-4000 files use ``rh_data = 128``: byte 131072).
The sample interval is ``range / n_samples``. The first two samples of every
trace hold a scan counter and a mark word, not signal: the reader replaces them
with the third sample (``metadata["header_samples_replaced"] = 2``), and lists the
traces whose mark word is set (the operator's marks, pressed at known distances) in
``metadata["marks"]`` (see :func:`gpr3d.core.gridsurvey.place_by_marks`).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
import struct
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError
from gpr3d.core.survey import Survey
from gpr3d.io._common import check_file, finite_positive, gps_positions, nmea_degrees, sidecar, whole_traces

__all__ = ["is_dzt", "read_dzt", "read_dzt_header", "read_dzg", "GSSI_ANTENNA_MHZ"]

HEADER_BYTES = 1024
MAX_CHANNELS = 16

#: GSSI antenna model codes and names -> nominal centre frequency (MHz); public product facts.
GSSI_ANTENNA_MHZ = {
    "3207": 100, "3207AP": 100, "5106": 200, "5106A": 200, "50270": 270, "50270S": 270,
    "50300": 300, "D50300": 300, "350": 350, "350HS": 350, "D400HS": 350, "5103": 400,
    "5103A": 400, "50400": 400, "50400S": 400, "3102": 500, "800": 800, "D50800": 800,
    "3101": 900, "3101A": 900, "51600": 1600, "51600S": 1600, "SS MINI": 1600,
    "4105NR": 2000, "42000S": 2000, "62000": 2000, "62000-003": 2000, "62300": 2300,
    "62300XT": 2300, "52600": 2600, "52600S": 2600, "SSMINIXT": 2700,
}

_MAIN = struct.Struct("<HHHHH5fH")  # bytes 0..31


def _decode_date(raw: bytes) -> str | None:
    """GSSI packed date: sec/2 (5 bits), min (6), hour (5), day (5), month (4), year-1980 (7)."""
    v = int.from_bytes(raw, "little")
    try:  # (an unset date, all zeros, has month 0: no date)
        d = _dt.datetime(
            1980 + (v >> 25), (v >> 21) & 0xF, (v >> 16) & 0x1F, (v >> 11) & 0x1F, (v >> 5) & 0x3F, 2 * (v & 0x1F)
        )
    except ValueError:
        return None
    return d.isoformat()


def _antenna_mhz(name: str) -> float | None:
    key = name.strip()
    if key in GSSI_ANTENNA_MHZ:
        return float(GSSI_ANTENNA_MHZ[key])
    m = re.match(r"^\D*?(\d+(?:\.\d+)?)\s*(MHz|GHz)", key, re.IGNORECASE)
    if m:
        return float(m.group(1)) * (1000.0 if m.group(2).lower() == "ghz" else 1.0)
    base = key.split("x")[0]
    if base in GSSI_ANTENNA_MHZ:
        return float(GSSI_ANTENNA_MHZ[base])
    return None


def read_dzt_header(path) -> dict:
    """Parse and validate the header of a DZT file; FormatError names any problem."""
    p = check_file(path)
    size = p.stat().st_size
    if size < HEADER_BYTES:
        raise FormatError(p, f"file is {size} bytes, shorter than one {HEADER_BYTES}-byte DZT header")
    with open(p, "rb") as f:
        head = f.read(HEADER_BYTES)
        (tag, rh_data, nsamp, bits, zero, sps, spm, mpm, position, range_ns, npass) = _MAIN.unpack(head[:32])
        nchan = struct.unpack("<H", head[52:54])[0]
        if not 1 <= nchan <= MAX_CHANNELS:
            raise FormatError(p, f"header gives {nchan} channels (expected 1..{MAX_CHANNELS}): not a DZT file or corrupt")
        if size < HEADER_BYTES * nchan:
            raise FormatError(p, f"file is {size} bytes, shorter than {nchan} channel headers")
        f.seek(0)
        heads = f.read(HEADER_BYTES * nchan)
    if bits not in (8, 16, 32):
        raise FormatError(p, f"header gives {bits} bits per sample (expected 8, 16 or 32): not a DZT file or corrupt")
    if nsamp < 2:
        raise FormatError(p, f"header gives {nsamp} samples per trace")
    range_ns = finite_positive(p, "range (ns)", range_ns)
    if range_ns > 1e6:
        raise FormatError(p, f"header range {range_ns:g} ns is implausible")
    offset = HEADER_BYTES * rh_data if rh_data < HEADER_BYTES else HEADER_BYTES * nchan
    if offset < HEADER_BYTES * nchan:
        raise FormatError(p, f"data offset {offset} lies inside the {nchan} channel header(s)")
    if offset > size:
        raise FormatError(p, f"data offset {offset} lies beyond the end of the file ({size} bytes)")
    for ch in range(1, nchan):  # each channel has a header of its own: a channel count read from samples finds none
        at = ch * HEADER_BYTES
        (_, _, n_k, bits_k, _, _, _, _, _, range_k, _) = _MAIN.unpack(heads[at : at + 32])
        if bits_k not in (8, 16, 32) or n_k < 2 or not (math.isfinite(range_k) and range_k > 0):
            raise FormatError(p, f"header gives {nchan} channels, but bytes {at}..{at + HEADER_BYTES - 1} hold no header "
                                 f"of channel {ch + 1} ({bits_k} bits, {n_k} samples, range {range_k:g} ns): the file "
                                 "holds fewer channels, or is corrupt")
    eps_r, top, depth = struct.unpack("<3f", head[54:66])
    antennas = []
    for ch in range(nchan):
        raw = heads[ch * HEADER_BYTES + 98 : ch * HEADER_BYTES + 112]
        antennas.append(raw.split(b"\x00")[0].decode("latin-1").strip())
    vsbyte = head[113]
    hdr = {
        "tag": tag,
        "data_offset": offset,
        "n_samples": nsamp,
        "bits": bits,
        "zero": zero,
        "scans_per_s": sps if math.isfinite(sps) and sps > 0 else None,
        "scans_per_m": spm if math.isfinite(spm) and spm > 0 else None,
        "m_per_mark": mpm if math.isfinite(mpm) else None,
        "position_ns": position if math.isfinite(position) else None,
        "range_ns": range_ns,
        "n_channels": nchan,
        "eps_r": float(eps_r) if math.isfinite(eps_r) and 1.0 <= eps_r <= 100.0 else None,
        "antennas": antennas,
        "created": _decode_date(head[32:36]),
        "modified": _decode_date(head[36:40]),
        "system_code": vsbyte >> 3,
        "file_name": head[114:126].split(b"\x00")[0].decode("latin-1"),
        "file_bytes": size,
    }
    return hdr


def is_dzt(path) -> bool:
    """True if the file parses as a DZT header and its size fits whole traces roughly."""
    try:
        hdr = read_dzt_header(path)
    except Exception:  # noqa: BLE001 - detection never raises
        return False
    if Path(path).suffix.lower() == ".dzt":
        return True
    trace_bytes = hdr["n_samples"] * hdr["bits"] // 8 * hdr["n_channels"]
    return (hdr["file_bytes"] - hdr["data_offset"]) >= trace_bytes


_GSSIS = re.compile(r"^\$GSSIS,(\d+),")


def read_dzg(path) -> dict:
    """Parse a DZG sidecar: ``$GSSIS,<scan>,...`` records each followed by NMEA sentences.

    Returns ``{"scan": (k,), "lat": (k,), "lon": (k,), "alt": (k,), "records": n,
    "malformed": m}`` holding only records with a GPS fix (GGA quality > 0).
    """
    p = check_file(path)
    scans, lat, lon, alt = [], [], [], []
    records = malformed = 0
    current = None
    text = p.read_bytes().decode("latin-1", errors="replace")
    for line in text.splitlines():
        line = line.strip()
        if not line:
            continue
        m = _GSSIS.match(line)
        if m:
            current = int(m.group(1))
            records += 1
            continue
        if current is not None and line[3:6] == "GGA" and line.startswith("$"):
            parts = line.split("*")[0].split(",")
            try:
                quality = int(parts[6])
                if quality > 0:
                    la = nmea_degrees(parts[2], parts[3])
                    lo = nmea_degrees(parts[4], parts[5])
                    al = float(parts[9]) if parts[9] else 0.0
                    scans.append(current), lat.append(la), lon.append(lo), alt.append(al)
            except (IndexError, ValueError):
                malformed += 1
            current = None
    return {
        "scan": np.asarray(scans, dtype=float),
        "lat": np.asarray(lat),
        "lon": np.asarray(lon),
        "alt": np.asarray(alt),
        "records": records,
        "malformed": malformed,
    }


def read_dzt(path, *, gps: bool = True) -> list[Survey]:
    """Read every channel of a DZT file as a list of :class:`~gpr3d.core.survey.Survey`.

    Positions come from the DZG sidecar when it holds at least two GPS fixes
    (local east-north-up metres about the first fix), else from the survey wheel
    (``scans_per_m``) along the world x axis, else they are left empty.
    """
    p = check_file(path)
    hdr = read_dzt_header(p)
    nchan, nsamp, bits = hdr["n_channels"], hdr["n_samples"], hdr["bits"]
    trace_bytes = nsamp * (bits // 8) * nchan
    n = whole_traces(p, hdr["file_bytes"] - hdr["data_offset"], trace_bytes, "trace")
    dtype = {8: "<u1", 16: "<u2", 32: "<i4"}[bits]
    binary_zero = {8: 128.0, 16: 32768.0, 32: 0.0}[bits]
    # read block by block into each channel's float32 array: the samples cost those arrays and one block (the whole
    # file read at once, then converted, once peaked at 3.7 times a 3 GiB file)
    channels = [np.empty((n, nsamp), np.float32) for _ in range(nchan)]
    mark_word = np.zeros(n, dtype)  # the second sample of the first channel
    block = max(1, (32 << 20) // trace_bytes)
    with open(p, "rb") as fh:
        fh.seek(hdr["data_offset"])
        for i in range(0, n, block):
            k = min(block, n - i)
            raw = np.fromfile(fh, dtype=dtype, count=k * nsamp * nchan)
            if raw.size != k * nsamp * nchan:
                raise FormatError(p, "file shrank while being read")
            raw = raw.reshape(k, nchan, nsamp)
            for ch in range(nchan):
                np.subtract(raw[:, ch, :], np.float32(binary_zero), out=channels[ch][i : i + k], dtype=np.float32)
            if nsamp > 2:
                mark_word[i : i + k] = raw[:, 0, 1]

    dt = hdr["range_ns"] * 1e-9 / nsamp
    timestamps = np.arange(n) / hdr["scans_per_s"] if hdr["scans_per_s"] else None
    positions = None
    pos_source = None
    meta_gps = None
    dzg = sidecar(p, ".dzg") if gps else None
    if dzg is not None:
        try:
            g = read_dzg(dzg)
        except FormatError:
            g = None
        if g is not None:
            meta_gps = {"file": dzg.name, "records": g["records"], "fixes": int(g["scan"].size),
                        "malformed": g["malformed"]}
            positions, origin = gps_positions(g["scan"], g["lat"], g["lon"], g["alt"], np.arange(n))
            if positions is not None:
                pos_source = "DZG GPS (local ENU metres about origin)"
                meta_gps["origin_lat_lon_alt"] = list(origin)
    if positions is None and hdr["scans_per_m"]:
        positions = np.zeros((n, 3))
        positions[:, 0] = np.arange(n) / hdr["scans_per_m"]
        pos_source = "survey wheel (header scans per metre), along world x"

    # the mark word (second sample) of the first channel: nonzero where the operator pressed the mark button
    marks = np.nonzero(mark_word)[0].tolist()
    surveys = []
    for ch in range(nchan):
        data = channels[ch]
        if nsamp > 2:
            data[:, :2] = data[:, 2:3]
        ant = hdr["antennas"][ch]  # (one name per channel header)
        mhz = _antenna_mhz(ant)
        meta = {
            "format": "dzt",
            "path": str(p),
            "channel": ch,
            "n_channels": nchan,
            "antenna": ant,
            "bits": bits,
            "range_s": hdr["range_ns"] * 1e-9,
            "position_s": None if hdr["position_ns"] is None else hdr["position_ns"] * 1e-9,
            "scans_per_s": hdr["scans_per_s"],
            "scans_per_m": hdr["scans_per_m"],
            "created": hdr["created"],
            "system_code": hdr["system_code"],
            "data_offset": hdr["data_offset"],
            "positions_source": pos_source,
            "header_samples_replaced": 2 if nsamp > 2 else 0,
            "marks": marks,
        }
        if meta_gps is not None:
            meta["gps"] = meta_gps
        surveys.append(
            Survey(
                data=data,
                dt_s=dt,
                timestamps_s=timestamps,
                positions_xyz=positions,
                frequency_hz=None if mhz is None else mhz * 1e6,
                eps_r=hdr["eps_r"],
                metadata=meta,
            )
        )
    return surveys
