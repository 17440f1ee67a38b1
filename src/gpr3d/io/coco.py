"""COCO detection JSON and the mapping between B-scan boxes and image pixels.

A B-scan box is ``[trace_start, t_start_s, trace_end, t_end_s]`` (CONVENTIONS.md:
trace indices 0-based, times in seconds from the first recorded sample). An image
of a B-scan has one column per trace (or a resampled span of traces) and ``height``
rows spanning a time span; :class:`PixelMap` converts both ways, so simulation
(labels -> COCO), detection (network boxes -> B-scan boxes) and users' own labels
(screenshots with a given mapping) share one definition.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CATEGORIES", "PixelMap", "coco_dataset", "BOX_HALF_ANGLE_DEG", "BOX_PAD_PERIODS"]

#: the label box rule (docs/labels.md), shared by the labeller and the detector's apex estimate:
#: traces within depth * tan(45 deg) of the target, time from this many periods before the apex
BOX_HALF_ANGLE_DEG = 45.0
BOX_PAD_PERIODS = 0.7

#: target kinds of the labels; detectors may merge them into one class
CATEGORIES = ["rebar", "steel_pipe", "pvc_pipe", "void", "tank"]


@dataclass(frozen=True)
class PixelMap:
    """Affine map between B-scan coordinates and image pixels.

    Column ``c`` (pixel centre) shows trace ``trace0 + c * traces_per_px``; row ``r``
    shows time ``t0_s + r * s_per_px``. Boxes in pixels are ``[x0, y0, x1, y1]``
    (corners, as torchvision); in COCO they are ``[x, y, w, h]``.
    """

    trace0: float = 0.0
    traces_per_px: float = 1.0
    t0_s: float = 0.0
    s_per_px: float = 1.0

    def box_to_px(self, box) -> list[float]:
        i0, ta, i1, tb = (float(v) for v in box)
        return [(i0 - self.trace0) / self.traces_per_px, (ta - self.t0_s) / self.s_per_px,
                (i1 - self.trace0) / self.traces_per_px, (tb - self.t0_s) / self.s_per_px]

    def px_to_box(self, px) -> list[float]:
        x0, y0, x1, y1 = (float(v) for v in px)
        return [self.trace0 + x0 * self.traces_per_px, self.t0_s + y0 * self.s_per_px,
                self.trace0 + x1 * self.traces_per_px, self.t0_s + y1 * self.s_per_px]

    def point_to_px(self, trace: float, time_s: float) -> tuple[float, float]:
        return (trace - self.trace0) / self.traces_per_px, (time_s - self.t0_s) / self.s_per_px

    def px_to_point(self, x: float, y: float) -> tuple[float, float]:
        return self.trace0 + x * self.traces_per_px, self.t0_s + y * self.s_per_px


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
        pm = PixelMap(s_per_px=row_s)
        images.append({"id": s["id"], "file_name": s["file_name"], "width": s["n_traces"], "height": image_height,
                       "eps_r": s["eps_r"], "row_s": row_s})
        for lab in s["labels"]:
            if not lab["visible"]:
                continue
            x0, y0, x1, y1 = pm.box_to_px(lab["box"])
            x, y, w, h = x0, y0, x1 - x0, y1 - y0
            anns.append({"id": len(anns) + 1, "image_id": s["id"], "category_id": lab["category"],
                         "bbox": [x, y, w, h], "area": w * h, "iscrowd": 0,
                         "apex_trace": lab["apex_trace"], "apex_time_s": lab["apex_time_s"],
                         "depth_m": lab["depth_m"]})
    cats = [{"id": i + 1, "name": n, "supercategory": "target"} for i, n in enumerate(CATEGORIES)]
    return {"info": {"description": "gpr3d simulated B-scans"}, "images": images, "annotations": anns,
            "categories": cats}
