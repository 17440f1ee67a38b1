"""SEG-Y export (through segyio) for interchange with seismic and GPR software.

SEG-Y stores the sample interval as a 16-bit integer in microseconds, too coarse
for GPR. Like most GPR software, gpr3d scales time: the interval field holds
picoseconds (so the trace "duration" reads in nanoseconds where a seismic program
expects milliseconds). The textual header says so. Samples are IEEE float32;
antenna midpoints go to the source/group/CDP coordinates in millimetres
(scalar -1000), the elevation to the receiver group elevation (mm).
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.deps import require
from gpr3d.core.errors import InvalidDataError
from gpr3d.io.atomic import atomic_path

__all__ = ["write_segy"]


def write_segy(survey, path) -> None:
    """Write ``survey`` to a SEG-Y rev 1 file (IEEE float, picosecond sample interval), atomically."""
    segyio = require("segyio")
    dt_ps = int(round(survey.dt_s * 1e12))
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
        f"C 1 GPR DATA WRITTEN BY GPR3D\n"
        f"C 2 TIME UNIT: SAMPLE INTERVAL FIELD IN PICOSECONDS (DT = {survey.dt_s * 1e9:.6g} NS)\n"
        f"C 3 TRACES {n} SAMPLES {ns} TIME ZERO {survey.t0_s * 1e9:.6g} NS\n"
        f"C 4 COORDINATES: ANTENNA MIDPOINT IN MM (SCALAR -1000), WORLD FRAME Z UP\n"
        f"C 5 CENTRE FREQUENCY MHZ {0 if survey.frequency_hz is None else survey.frequency_hz / 1e6:.6g}"
        f" TX-RX OFFSET M {survey.offset_m:.6g}\n"
        f"C 6 SOURCE {str(survey.metadata.get('format', '')).upper()} "
        f"{str(survey.metadata.get('path', ''))[-50:].upper()}\n"
    )
    with atomic_path(path, suffix=".sgy.part") as tmp:
        with segyio.create(str(tmp), spec) as f:
            f.text[0] = segyio.tools.create_text_header(
                {i + 1: line[4:] for i, line in enumerate(text.strip().splitlines())}
            )
            f.bin.update({segyio.BinField.Interval: dt_ps, segyio.BinField.Samples: ns,
                          segyio.BinField.Format: 5, segyio.BinField.SEGYRevision: 0x0100})
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
