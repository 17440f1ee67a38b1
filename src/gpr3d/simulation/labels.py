"""Ground-truth labels of a simulated B-scan: hyperbola apexes, boxes, depths, COCO export.

Travel times are exact for the scene's geometry: for every trace, the shortest
path transmitter -> target surface -> receiver through the host (antennas on the
surface, straight rays; a cylinder crossing the line is a circle in the x-z
plane). The recorded time adds the source delay: gprMax's Ricker pulse peaks
``sqrt(2)/f`` after the start of the simulation.

COCO export lives in :mod:`gpr3d.io.coco` (shared with detection).

Box rule (see ``docs/labels.md`` for the figure): the box spans the traces whose
antenna midpoint lies within ``(depth_to_centre) * tan(45 deg)`` of the target
axis (the part of the hyperbola a broadside antenna sees well), and in time from
``0.7 / f`` before the apex to ``0.7 / f`` after the latest arrival over those
traces (the Ricker wavelet's main lobes), clipped to the record.
"""

from __future__ import annotations

import json
import math

import numpy as np

from gpr3d.io.coco import BOX_HALF_ANGLE_DEG, BOX_PAD_PERIODS, CATEGORIES, coco_dataset  # noqa: F401 (re-exported)
from gpr3d.simulation.scene import Scene

__all__ = ["hyperbola_times", "label_scene", "label_traces", "coco_dataset", "BOX_HALF_ANGLE_DEG", "BOX_PAD_PERIODS"]


def _circle_path(tx_x, rx_x, cx, cz, r, n_angles=721):
    """Shortest tx -> circle -> rx path length (m) for antennas on z = 0; arrays over traces."""
    ang = np.linspace(0.0, np.pi, n_angles)  # upper half: the side facing the surface
    px = cx + r * np.cos(ang)[None, :]
    pz = cz + r * np.sin(ang)[None, :]
    d = np.hypot(px - tx_x[:, None], pz) + np.hypot(px - rx_x[:, None], pz)
    k = np.argmin(d, axis=1)
    best = d[np.arange(d.shape[0]), k]
    # parabolic refinement between neighbouring angles
    inner = (k > 0) & (k < n_angles - 1)
    i = np.nonzero(inner)[0]
    y0, y1, y2 = d[i, k[i] - 1], d[i, k[i]], d[i, k[i] + 1]
    den = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        best[i] = np.where(den > 0, y1 - (y0 - y2) ** 2 / (8 * den), y1)
    return best


def hyperbola_times(scene: Scene, target, x=None) -> np.ndarray:
    """Two-way time (s, below the surface) to ``target`` for every trace (midpoints ``x``, default the scene's)."""
    x = scene.trace_midpoints_x() if x is None else np.asarray(x, dtype=float)
    half = scene.antenna.offset_m / 2
    path = _circle_path(x - half, x + half, target.x_m, -(target.depth_m + target.radius_m), target.radius_m)
    return path / scene.medium.velocity_m_s


def label_scene(scene: Scene, n_samples: int, dt_s: float) -> list[dict]:
    """Labels of every target of ``scene`` for a record of ``n_samples`` at ``dt_s`` (its own trace positions).

    Each label: ``kind, category, apex_trace, apex_time_s`` (from the first sample),
    ``apex_twt_s`` (below the surface), ``depth_m`` (to the top), ``x_m``,
    ``radius_m``, ``box = [trace_start, t_start_s, trace_end, t_end_s]``, ``visible``
    (the apex lies inside the record).
    """
    return label_traces(scene, scene.trace_midpoints_x(), n_samples, dt_s)


def label_traces(scene: Scene, x, n_samples: int, dt_s: float, *, source_delay_s: float | None = None,
                 pad_periods: float = BOX_PAD_PERIODS) -> list[dict]:
    """Labels (as :func:`label_scene`) for traces at antenna midpoints ``x`` (non-decreasing, m).

    ``source_delay_s`` is the time from the first sample to the pulse's peak at the
    source (default gprMax's ``sqrt(2)/f``). Uneven steps, stops (repeated
    positions) and gaps are allowed; ``apex_trace`` is then the fractional trace
    index at which the antenna passes over the target. ``pad_periods``: the box's
    time reaches this many periods ``1 / f`` before the apex and after the latest
    arrival (default the rule's ``BOX_PAD_PERIODS``, 0.7: the wavelet's main lobes;
    0.4 stops at the Ricker's side lobes' peaks, ``0.39 / f`` from its own).
    """
    if not (math.isfinite(pad_periods) and 0.0 <= pad_periods <= 2.0):
        raise ValueError(f"pad_periods must lie in 0..2 periods, got {pad_periods!r}")
    f = scene.antenna.frequency_hz
    delay = math.sqrt(2) / f if source_delay_s is None else float(source_delay_s)
    x = np.asarray(x, dtype=float)
    n = x.size
    t_end = (n_samples - 1) * dt_s
    idx = np.arange(n, dtype=float)
    xu, first = np.unique(x, return_index=True)  # positions repeat where the cart stopped
    out = []
    for t in scene.targets:
        reach = (t.depth_m + t.radius_m) * math.tan(math.radians(BOX_HALF_ANGLE_DEG))
        sel = np.nonzero(np.abs(x - t.x_m) <= reach)[0]
        if sel.size == 0:  # the line passes beside the target: its nearest trace
            sel = np.array([int(np.argmin(np.abs(x - t.x_m)))])
        twt = hyperbola_times(scene, t, x[sel])  # the apex trace lies inside the reach
        apex_trace = float(np.interp(t.x_m, xu, idx[first])) if xu.size > 1 else 0.0
        if t.x_m < x[0] or t.x_m > x[-1]:  # outside the line: extrapolate with the mean step
            step = (x[-1] - x[0]) / max(n - 1, 1) or 1.0
            apex_trace = (t.x_m - x[0]) / step
        apex_twt = float(twt.min())
        t0 = delay + apex_twt - pad_periods / f
        t1 = delay + float(twt.max()) + pad_periods / f
        out.append({
            "kind": t.kind,
            "category": CATEGORIES.index(t.kind) + 1,
            "apex_trace": apex_trace,
            "apex_time_s": delay + apex_twt,
            "apex_twt_s": apex_twt,
            "depth_m": t.depth_m,
            "x_m": t.x_m,
            "radius_m": t.radius_m,
            "box": [int(sel[0]), max(t0, 0.0), int(sel[-1]), min(t1, t_end)],
            "visible": bool(0 <= delay + apex_twt <= t_end and 0 <= apex_trace <= n - 1),
        })
    return out


def to_json(obj) -> str:
    return json.dumps(obj, indent=1)
