"""SEG-Y both ways (through segyio) for interchange with seismic and GPR software.

SEG-Y stores the sample interval as a 16-bit integer in microseconds, too coarse
for GPR. Like most GPR software, gpr3d scales time: the interval field holds
picoseconds (so the trace "duration" reads in nanoseconds where a seismic program
expects milliseconds). The textual header says so. A 16-bit integer cannot hold
93.75 ps (a 0.27 % time error once rounded), so gpr3d also writes SEG-Y rev 2's
**extended sample interval** (bytes 3281-3288 of the binary header, an IEEE double
in the same unit, picoseconds) and marks the file revision 2.0; rev 2 readers take
the interval from there, and gpr3d's reader does too. The textual header also
carries the exact interval, time zero, centre frequency and antenna offset in
full precision, so that a gpr3d round trip is exact. Samples are IEEE float32;
antenna midpoints go to the source/group/CDP coordinates in millimetres (scalar
-1000), the elevation to the receiver group elevation (mm).

Reading (:func:`read_segy`): IEEE or IBM floats or integers, big- or little-endian;
the interval from the extended field where a rev 2 file has one, else the 16-bit
field, in ``dt_unit``: by default picoseconds (the GPR convention above), nanoseconds
where the textual header says so; a seismic file (microseconds) is refused.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

from gpr3d.core.atomic import atomic_path
from gpr3d.core.deps import require
from gpr3d.core.errors import FormatError, InvalidDataError

__all__ = ["write_segy", "read_segy", "is_segy"]

#: byte offset of SEG-Y rev 2's extended sample interval (IEEE double) in the file (3200-byte text header first)
EXT_INTERVAL_AT = 3200 + 80
#: byte offset of the SEG-Y format revision (major, minor bytes)
REVISION_AT = 3200 + 300
_MARK = "GPR DATA WRITTEN BY GPR3D"


def write_segy(survey, path) -> None:
    """Write ``survey`` to a SEG-Y rev 1 file (IEEE float, picosecond sample interval), atomically."""
    segyio = require("segyio")
    dt_ps = int(round(survey.dt_s * 1e12))  # the 16-bit field, for readers that know only it
    if not 1 <= dt_ps <= 65535:
        raise InvalidDataError(f"sample interval {survey.dt_s:g} s does not fit SEG-Y's 16-bit picosecond field")
    n, ns = survey.shape
    if ns > 65535:
        raise InvalidDataError(f"{ns} samples per trace exceed SEG-Y's 16-bit sample count")
    spec = segyio.spec()
    spec.format = 5
    spec.samples = np.arange(ns) * dt_ps / 1000.0  # "ms" axis holding ns
    spec.tracecount = n
    pos_mm = None if survey.positions_xyz is None else np.round(survey.positions_xyz * 1000).astype(np.int64)
    if pos_mm is not None and np.abs(pos_mm).max() >= 2**31:
        raise InvalidDataError("positions exceed SEG-Y's coordinate range (|x| < 2147 km in mm)")
    text = (
        f"C 1 {_MARK}\n"
        f"C 2 TIME UNIT: SAMPLE INTERVAL FIELD IN PICOSECONDS, EXACT IN BYTES 3281-3288 (REV 2)\n"
        f"C 3 TRACES {n} SAMPLES {ns}\n"
        f"C 4 COORDINATES: ANTENNA MIDPOINT IN MM (SCALAR -1000), WORLD FRAME Z UP\n"
        f"C 5 DT S {survey.dt_s!r}\n"
        f"C 6 T0 S {float(survey.t0_s)!r}\n"
        f"C 7 FREQUENCY HZ {0.0 if survey.frequency_hz is None else float(survey.frequency_hz)!r}\n"
        f"C 8 OFFSET M {float(survey.offset_m)!r}\n"
        f"C 9 SOURCE {str(survey.metadata.get('format', '')).upper()} "
        f"{str(survey.metadata.get('path', ''))[-50:].upper()}\n"
    )
    with atomic_path(path, suffix=".sgy.part") as tmp:
        with segyio.create(str(tmp), spec) as f:
            f.text[0] = segyio.tools.create_text_header(
                {i + 1: line[4:] for i, line in enumerate(text.strip().splitlines())}
            )
            f.bin.update({segyio.BinField.Interval: dt_ps, segyio.BinField.Samples: ns,
                          segyio.BinField.Format: 5, segyio.BinField.SEGYRevision: 2,
                          segyio.BinField.SEGYRevisionMinor: 0})
            TF = segyio.TraceField
            for i in range(n):
                h = {TF.TRACE_SEQUENCE_LINE: i + 1, TF.TRACE_SEQUENCE_FILE: i + 1, TF.FieldRecord: i + 1,
                     TF.TraceNumber: i + 1, TF.TRACE_SAMPLE_COUNT: ns, TF.TRACE_SAMPLE_INTERVAL: dt_ps,
                     TF.offset: int(round(survey.offset_m * 1000))}
                if pos_mm is not None:
                    x, y, z = (int(v) for v in pos_mm[i])
                    h.update({TF.SourceGroupScalar: -1000, TF.SourceX: x, TF.SourceY: y, TF.GroupX: x,
                              TF.GroupY: y, TF.CDP_X: x, TF.CDP_Y: y, TF.ElevationScalar: -1000,
                              TF.ReceiverGroupElevation: z})
                f.header[i] = h
            f.trace = np.ascontiguousarray(survey.data, dtype=np.float32)
        with open(tmp, "r+b") as raw:  # rev 2's extended interval: segyio has no field for it
            raw.seek(EXT_INTERVAL_AT)
            raw.write(struct.pack(">d", survey.dt_s * 1e12))


def is_segy(path) -> bool:
    """A ``.sgy``/``.segy`` file long enough for its headers with a plausible binary header."""
    p = Path(path)
    if p.suffix.lower() not in (".sgy", ".segy") or p.stat().st_size < 3600:
        return False
    with open(p, "rb") as f:
        f.seek(3200)
        binhdr = f.read(400)
    # samples per trace: unsigned (rev 2 allows 65535); the format code is small either way
    big = struct.unpack(">H", binhdr[20:22])[0], struct.unpack(">H", binhdr[24:26])[0]
    little = struct.unpack("<H", binhdr[20:22])[0], struct.unpack("<H", binhdr[24:26])[0]
    return any(ns > 0 and fmt in (1, 2, 3, 5, 8, 10, 11, 12, 16) for ns, fmt in (big, little))


def _text_value(text: str, key: str):
    m = re.search(rf"{key} (\S+)", text)
    if m is None:
        return None
    try:
        return float(m.group(1))
    except ValueError:
        return None


def read_segy(path, *, dt_unit: str = "auto") -> list:
    """Read a SEG-Y file as a one-element list of :class:`~gpr3d.core.survey.Survey`.

    ``dt_unit``: the unit of the file's sample interval fields, ``"auto"`` (picoseconds, as gpr3d and most GPR
    software write them, or nanoseconds where the textual header says so), ``"ps"``, ``"ns"`` or ``"us"``.
    """
    from gpr3d.core.survey import Survey
    from gpr3d.io._common import check_file, sample_interval

    segyio = require("segyio")
    units = {"ps": 1e-12, "ns": 1e-9, "us": 1e-6}
    if dt_unit not in ("auto", *units):
        raise InvalidDataError(f"dt_unit must be auto, ps, ns or us, got {dt_unit!r}")
    p = check_file(path)
    TF = segyio.TraceField
    failure = None
    for endian in ("big", "little"):
        try:
            with segyio.open(str(p), "r", ignore_geometry=True, strict=False, endian=endian) as f:
                data = np.asarray(f.trace.raw[:], dtype=np.float32).reshape(f.tracecount, -1)
                text = bytes(f.text[0]).decode("ascii", errors="replace")
                interval = int(f.bin[segyio.BinField.Interval])
                heads = [f.header[i] for i in range(f.tracecount)]
                if interval <= 0:  # (segyio opens no file without traces: heads[0] exists)
                    interval = int(heads[0][TF.TRACE_SAMPLE_INTERVAL])
            big_endian = endian == "big"
            break
        except (RuntimeError, OSError, ValueError, IndexError) as exc:  # (segyio: IndexError on 0 traces)
            failure = failure or exc  # the standard (big-endian) reading's reason, not the fallback's
    else:
        raise FormatError(p, f"not a readable SEG-Y file ({failure})")
    with open(p, "rb") as raw:
        raw.seek(EXT_INTERVAL_AT)
        ext = struct.unpack(">d" if big_endian else "<d", raw.read(8))[0]
        raw.seek(REVISION_AT)
        rev_major = raw.read(1)[0] if big_endian else raw.read(2)[1]
    ours = _MARK in text
    upper = text.upper()
    unit = dt_unit if dt_unit != "auto" else ("ns" if "NANOSECOND" in upper and "PICOSECOND" not in upper
                                              and not ours else "ps")
    dt_text = _text_value(text, "DT S") if ours else None
    if dt_text:
        dt, source = dt_text, "the textual header's DT S"
    elif rev_major >= 2 and np.isfinite(ext) and ext > 0:
        dt, source = ext * units[unit], f"the extended sample interval field (read as {unit})"
    elif interval > 0:
        dt, source = interval * units[unit], f"the sample interval field (read as {unit})"
    else:
        raise FormatError(p, "gives no sample interval (binary and trace headers hold 0)")
    if not np.all(np.isfinite(data)):
        raise FormatError(p, "holds NaN/inf samples")
    if dt > 1e-6:
        raise FormatError(p, f"sample interval {dt:g} s (the field read as {unit}) is no GPR interval: a seismic "
                             "file, or its interval unit is not the default (gpr3d.read(..., dt_unit=...))")
    dt = sample_interval(p, dt, source)

    def scaled(value, scalar):
        return value / -scalar if scalar < 0 else value * (scalar if scalar > 0 else 1)

    xyz = np.array([[scaled(h[TF.CDP_X] or h[TF.SourceX], h[TF.SourceGroupScalar]),
                     scaled(h[TF.CDP_Y] or h[TF.SourceY], h[TF.SourceGroupScalar]),
                     scaled(h[TF.ReceiverGroupElevation], h[TF.ElevationScalar])] for h in heads], float)
    positions = xyz if np.any(xyz != 0) else None
    freq = _text_value(text, "FREQUENCY HZ") if ours else None
    return [Survey(data=data, dt_s=float(dt), positions_xyz=positions,
                   t0_s=(_text_value(text, "T0 S") or 0.0) if ours else 0.0,
                   frequency_hz=freq or None, offset_m=(_text_value(text, "OFFSET M") or 0.0) if ours else 0.0,
                   metadata={"format": "segy", "path": str(p), "segy_revision": int(rev_major),
                             "dt_unit": unit, "written_by_gpr3d": ours})]
