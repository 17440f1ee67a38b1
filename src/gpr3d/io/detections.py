"""The detections file: what ``gpr3d detect`` writes and ``gpr3d reconstruct --boxes`` reads.

Contract (CONVENTIONS.md)::

    {"input": str, "n_traces": int, "dt_s": float, "channel": int,
     "permittivity": {...} (optional, from depth estimation),
     "targets": [{"box": [trace_start, t_start_s, trace_end, t_end_s], "score": s,
                  "apex_trace": i, "apex_time_s": t, "depth_m": d?, "x_m": x?, ...}, ...]}

one such object per channel, in a list for a multi-channel file. Trace indices are
0-based in file order; times count in seconds from the first recorded sample (no
time-zero shift). Unknown fields are kept as they are, so later stages can add
their own (``permittivity``, ``depth_m``) and still reach ``reconstruct``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.errors import FormatError
from gpr3d.core.jsonutil import jsonable

__all__ = ["read_detections", "write_detections", "read_boxes"]


def _check_channel(path, obj, k: int) -> dict:
    where = f"channel {k}: " if k else ""
    if not isinstance(obj, dict):
        raise FormatError(path, f"{where}expected an object with a 'targets' list")
    if not isinstance(obj.get("targets"), list):
        raise FormatError(path, f"{where}no 'targets' list (expected gpr3d detect output, or a list of boxes)")
    for j, t in enumerate(obj["targets"]):
        if not isinstance(t, dict) or "box" not in t:
            raise FormatError(path, f"{where}target {j} has no 'box'")
        score = t.get("score", 1.0)
        if not isinstance(score, (int, float)) or not math.isfinite(score):
            raise FormatError(path, f"{where}target {j} has a bad score {score!r}")
    return obj


def read_detections(path) -> list[dict]:
    """All channels of a detections file, each a dict with its ``targets`` (every field kept).

    A bare JSON list of boxes ``[[i0, t0, i1, t1], ...]`` reads as one channel whose
    targets have only a ``box``.
    """
    try:
        obj = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise FormatError(path, f"cannot read detections: {exc}") from None
    if isinstance(obj, list) and not obj:
        return [{"targets": []}]
    if isinstance(obj, list) and all(isinstance(o, dict) and "targets" in o for o in obj):
        return [_check_channel(path, o, k) for k, o in enumerate(obj)]
    if isinstance(obj, list):  # a bare list of boxes (or of {"box": ...} objects)
        items = [t if isinstance(t, dict) else {"box": t} for t in obj]
        return [_check_channel(path, {"targets": items}, 0)]
    return [_check_channel(path, obj, 0)]


def read_boxes(path, channel: int = 0) -> list:
    """The boxes of one channel of a detections file (contents checked by the consumer)."""
    chans = read_detections(path)
    if not 0 <= channel < len(chans):
        raise FormatError(path, f"has {len(chans)} channel(s); no channel {channel}")
    return [t["box"] for t in chans[channel]["targets"]]


def write_detections(results: list[dict], path) -> None:
    """Write detections atomically: one object for one channel, a list for several."""
    obj = results[0] if len(results) == 1 else results
    atomic_write_text(path, json.dumps(jsonable(obj), indent=1))
