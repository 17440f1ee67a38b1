"""Ground-truth labels of a simulated B-scan: hyperbola apexes, boxes, depths, COCO export.

Travel times are exact for the scene's geometry: for every trace, the shortest
path transmitter -> target surface -> receiver through the host (antennas on the
surface, straight rays; a cylinder crossing the line is a circle in the x-z
plane). The recorded time adds the source delay: gprMax's Ricker pulse peaks
``sqrt(2)/f`` after the start of the simulation.

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

from gpr3d.simulation.scene import Scene

__all__ = ["hyperbola_times", "label_scene", "coco_dataset", "BOX_HALF_ANGLE_DEG", "BOX_PAD_PERIODS"]

BOX_HALF_ANGLE_DEG = 45.0
BOX_PAD_PERIODS = 0.7
CATEGORIES = ["rebar", "steel_pipe", "pvc_pipe", "void", "tank"]


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


def hyperbola_times(scene: Scene, target) -> np.ndarray:
    """Two-way time (s, below the surface) to ``target`` for every trace of ``scene``."""
    x = scene.trace_midpoints_x()
    half = scene.antenna.offset_m / 2
    path = _circle_path(x - half, x + half, target.x_m, -(target.depth_m + target.radius_m), target.radius_m)
    return path / scene.medium.velocity_m_s


def label_scene(scene: Scene, n_samples: int, dt_s: float) -> list[dict]:
    """Labels of every target of ``scene`` for a record of ``n_samples`` at ``dt_s``.

    Each label: ``kind, category, apex_trace, apex_time_s`` (from the first sample),
    ``apex_twt_s`` (below the surface), ``depth_m`` (to the top), ``x_m``,
    ``radius_m``, ``box = [trace_start, t_start_s, trace_end, t_end_s]``, ``visible``
    (the apex lies inside the record).
    """
    f = scene.antenna.frequency_hz
    delay = math.sqrt(2) / f
    x = scene.trace_midpoints_x()
    t_end = (n_samples - 1) * dt_s
    out = []
    for t in scene.targets:
        twt = hyperbola_times(scene, t)
        k = int(np.argmin(twt))
        # fractional apex trace: the target axis position in trace units
        apex_trace = float((t.x_m - scene.x_start_m) / scene.trace_step_m)
        apex_twt = float(twt.min())
        reach = (t.depth_m + t.radius_m) * math.tan(math.radians(BOX_HALF_ANGLE_DEG))
        sel = np.nonzero(np.abs(x - t.x_m) <= reach)[0]
        if sel.size == 0:
            sel = np.array([k])
        t0 = delay + apex_twt - BOX_PAD_PERIODS / f
        t1 = delay + float(twt[sel].max()) + BOX_PAD_PERIODS / f
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
            "visible": bool(0 <= delay + apex_twt <= t_end and 0 <= apex_trace <= scene.n_traces - 1),
        })
    return out


def coco_dataset(samples: list[dict], image_height: int) -> dict:
    """COCO detection JSON for a list of ``{"id", "file_name", "n_traces", "dt_s", "n_samples", "eps_r", "labels"}``.

    Images are ``n_traces`` pixels wide and ``image_height`` tall (the record resampled
    in time; ``row_s`` per image gives seconds per row); boxes are ``[x, y, w, h]`` in
    pixels, trace ``i`` at column ``i``. Extra fields: per annotation ``apex_trace``,
    ``apex_time_s``, ``depth_m``; per image ``eps_r`` (CONVENTIONS.md).
    """
    images, anns = [], []
    for s in samples:
        # row r shows time r * (n_samples - 1) * dt / (image_height - 1)
        row_s = (s["n_samples"] - 1) * s["dt_s"] / (image_height - 1)
        sy = 1.0 / row_s
        images.append({"id": s["id"], "file_name": s["file_name"], "width": s["n_traces"], "height": image_height,
                       "eps_r": s["eps_r"], "row_s": row_s})
        for lab in s["labels"]:
            if not lab["visible"]:
                continue
            i0, ta, i1, tb = lab["box"]
            x, y = float(i0), float(ta * sy)
            w, h = float(i1 - i0), float((tb - ta) * sy)
            anns.append({"id": len(anns) + 1, "image_id": s["id"], "category_id": lab["category"],
                         "bbox": [x, y, w, h], "area": w * h, "iscrowd": 0,
                         "apex_trace": lab["apex_trace"], "apex_time_s": lab["apex_time_s"],
                         "depth_m": lab["depth_m"]})
    cats = [{"id": i + 1, "name": n, "supercategory": "target"} for i, n in enumerate(CATEGORIES)]
    return {"info": {"description": "gpr3d simulated B-scans"}, "images": images, "annotations": anns,
            "categories": cats}


def to_json(obj) -> str:
    return json.dumps(obj, indent=1)
