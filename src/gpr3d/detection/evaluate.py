"""Detector evaluation on whole records: COCO metrics (class-agnostic and class-averaged) and apex recall.

Each record is one COCO image whose pixels are traces (x) and samples (y); IoU
does not change when an axis is scaled, so the metrics are those of the record
itself, whatever the window size. ``pycocotools`` computes mAP@0.5, mAP@0.75 (one class,
``hyperbola``; all box sizes), AR@10 and AR@100.

For a detector that names kinds, ``by_kind`` holds the same metrics averaged over the kinds
the true boxes hold, a box counting only under the kind it stands under: each box stands
under the kind it names at its score (as the detect contract reports it) and once more
under every other kind it gives a share of (``kind_shares``) at its score times that
share, as a multi-class detector offers its other readings. ``by_kind_top``: each box
under the kind it names alone.

Apex recall: a true apex counts as found when a detection (score >= the
threshold) has its apex within ``apex_traces`` traces and a quarter period
(``1 / (4 f)``) of it, matched one to one (greedy by score); every unmatched
detection is a false target, reported per true target.
"""

from __future__ import annotations

import contextlib
import io
import time

import numpy as np

from gpr3d.core.deps import require

__all__ = ["coco_metrics", "apex_matches", "box_matches", "kind_shares", "kind_rows", "evaluate_detector"]


def coco_metrics(gt_boxes: list[np.ndarray], det_boxes: list[np.ndarray], det_scores: list[np.ndarray], *,
                 gt_kinds=None, det_kinds=None, kinds=None) -> dict:
    """mAP@0.5, mAP@0.75, mAP@[.5:.95], AR@1, AR@10, AR@100 and recall@0.5 for boxes ``[x0, y0, x1, y1]`` per image.

    One class unless ``kinds`` (the category names) is given with per-image ``gt_kinds`` and
    ``det_kinds`` (lists of names): then each metric is the mean over the kinds that hold a
    true box (pycocotools' class average). ``recall@0.5``: the share of true boxes matched
    at IoU >= 0.5 by any of the 100 best detections of their image, whatever the score.
    """
    cats = list(kinds) if kinds else ["hyperbola"]

    def cat(names, k, j):
        return 1 if not kinds else cats.index(names[k][j]) + 1
    require("pycocotools")
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    images, anns, dets = [], [], []
    for k, g in enumerate(gt_boxes):
        g = np.asarray(g, float).reshape(-1, 4)
        w = float(max(g[:, 2].max() if len(g) else 1.0, 1.0)) + 1
        h = float(max(g[:, 3].max() if len(g) else 1.0, 1.0)) + 1
        images.append({"id": k + 1, "width": w, "height": h})
        for j, b in enumerate(g):
            bw, bh = float(b[2] - b[0]), float(b[3] - b[1])
            anns.append({"id": len(anns) + 1, "image_id": k + 1, "category_id": cat(gt_kinds, k, j),
                         "bbox": [float(b[0]), float(b[1]), bw, bh], "area": bw * bh, "iscrowd": 0})
        for j, (b, s) in enumerate(zip(np.asarray(det_boxes[k], float).reshape(-1, 4),
                                       np.asarray(det_scores[k], float).reshape(-1))):
            dets.append({"image_id": k + 1, "category_id": cat(det_kinds, k, j),
                         "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])], "score": float(s)})
    quiet = io.StringIO()
    with contextlib.redirect_stdout(quiet):
        gt = COCO()
        gt.dataset = {"images": images, "annotations": anns,
                      "categories": [{"id": i + 1, "name": n} for i, n in enumerate(cats)]}
        gt.createIndex()
        if not dets:
            return {"mAP@0.5": 0.0, "mAP@0.75": 0.0, "mAP": 0.0, "AR@1": 0.0, "AR@10": 0.0, "AR@100": 0.0,
                    "recall@0.5": 0.0}
        dt = gt.loadRes(dets)
        ev = COCOeval(gt, dt, "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    s = ev.stats
    rec = ev.eval["recall"][0, :, 0, -1]  # IoU 0.5, every kind, all areas, 100 detections
    rec = rec[rec > -1]
    return {"mAP": float(s[0]), "mAP@0.5": float(s[1]), "mAP@0.75": float(s[2]), "AR@1": float(s[6]),
            "AR@10": float(s[7]), "AR@100": float(s[8]), "recall@0.5": float(rec.mean()) if rec.size else 0.0}


def apex_matches(true_apexes, found_apexes, found_scores, *, max_traces: float, max_s: float,
                 return_found: bool = False):
    """``(true apexes found, false detections)``: one-to-one greedy matching by score.

    With ``return_found`` a third item: a boolean per true apex, found or not.
    """
    true = np.asarray(true_apexes, float).reshape(-1, 2)
    found = np.asarray(found_apexes, float).reshape(-1, 2)
    used = np.zeros(len(true), bool)
    false = 0
    for j in np.argsort(-np.asarray(found_scores, float).reshape(-1), kind="stable"):
        if len(true):
            d_tr = np.abs(true[:, 0] - found[j, 0])
            d_t = np.abs(true[:, 1] - found[j, 1])
            ok = (~used) & (d_tr <= max_traces) & (d_t <= max_s)
            if ok.any():
                cand = np.nonzero(ok)[0]
                used[cand[np.argmin(d_tr[cand] / max_traces + d_t[cand] / max_s)]] = True
                continue
        false += 1
    if return_found:
        return int(used.sum()), false, used
    return int(used.sum()), false


def box_matches(true_boxes, true_kinds, found_boxes, found_kinds, found_scores, *, iou: float = 0.5):
    """One-to-one matching of found boxes to true ones at IoU >= ``iou``, best score first.

    Boxes ``[x0, y0, x1, y1]`` in one unit per axis (traces and samples, say). Returns a list, per
    true box, of ``None`` (missed) or ``(found index, IoU, kind right)``.
    """
    true = np.asarray(true_boxes, float).reshape(-1, 4)
    found = np.asarray(found_boxes, float).reshape(-1, 4)
    out: list = [None] * len(true)
    for j in np.argsort(-np.asarray(found_scores, float).reshape(-1), kind="stable"):
        free = [k for k in range(len(true)) if out[k] is None]
        if not free:
            break
        b = found[j]
        ix = np.clip(np.minimum(true[free, 2], b[2]) - np.maximum(true[free, 0], b[0]), 0, None)
        iy = np.clip(np.minimum(true[free, 3], b[3]) - np.maximum(true[free, 1], b[1]), 0, None)
        inter = ix * iy
        union = (true[free, 2] - true[free, 0]) * (true[free, 3] - true[free, 1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
        v = np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)
        k = int(np.argmax(v))
        if v[k] >= iou:
            out[free[k]] = (int(j), float(v[k]), true_kinds[free[k]] == found_kinds[j])
    return out


def kind_shares(target: dict) -> dict:
    """A detection's share of each kind (the detect contract's ``kind_shares``); one that has none (a one-class
    detector's, or one written before them): all of it its ``kind``."""
    return target.get("kind_shares") or {target.get("kind", "target"): 1.0}


def kind_rows(target: dict) -> list[tuple[str, float]]:
    """The ``(kind, score)`` a detection stands under in the class-averaged metrics: its named kind at its score, and
    every other kind it gives a share of at its score times that share."""
    named = target.get("kind", "target")
    return [(named, target["score"])] + [(k, target["score"] * p) for k, p in kind_shares(target).items()
                                         if p > 0 and k != named]


def evaluate_detector(detector, records, *, score_threshold: float = 0.5, apex_traces: float = 3.0,
                      log=None) -> dict:
    """Metrics of ``detector`` over ``records`` (iterable of ``(Survey, labels)``), with per-record rows."""
    gts, dboxes, dscores, rows, gkinds, dkinds = [], [], [], [], [], []
    kboxes, kscores, kkinds = [], [], []  # a row a target and kind: the class-averaged metrics' detections
    found_total = true_total = false_total = 0
    by_kind: dict = {}
    t_windows = n_windows = 0.0
    for k, (survey, labels) in enumerate(records):
        vis = [lab for lab in labels["labels"] if lab.get("visible", True)]
        to_px = np.array([1.0, 1.0 / survey.dt_s, 1.0, 1.0 / survey.dt_s])
        gts.append(np.asarray([lab["box"] for lab in vis], float).reshape(-1, 4) * to_px)
        t0 = time.perf_counter()
        res = detector.detect(survey, score_threshold=0.0)
        t_windows += time.perf_counter() - t0
        n_windows += res["n_windows"]
        tg = res["targets"]
        dboxes.append(np.asarray([t["box"] for t in tg], float).reshape(-1, 4) * to_px)
        dscores.append(np.asarray([t["score"] for t in tg], float))
        gkinds.append([lab.get("kind", "target") for lab in vis])
        dkinds.append([t.get("kind", "target") for t in tg])
        per_kind = [(t["box"], score, kind) for t in tg for kind, score in kind_rows(t)]
        kboxes.append(np.asarray([b for b, _, _ in per_kind], float).reshape(-1, 4) * to_px)
        kscores.append(np.asarray([s for _, s, _ in per_kind], float))
        kkinds.append([k for _, _, k in per_kind])
        sel = [t for t in tg if t["score"] >= score_threshold]
        quarter = 0.25 / (survey.frequency_hz or 1e9)
        found, false, hit = apex_matches([[lab["apex_trace"], lab["apex_time_s"]] for lab in vis],
                                         [[t["apex_trace"], t["apex_time_s"]] for t in sel], [t["score"] for t in sel],
                                         max_traces=apex_traces, max_s=quarter, return_found=True)
        for lab, h in zip(vis, hit):
            n_f = by_kind.setdefault(lab.get("kind", "target"), [0, 0])
            n_f[0] += int(h)
            n_f[1] += 1
        found_total += found
        true_total += len(vis)
        false_total += false
        rows.append({"record": k, "n_true": len(vis), "n_detected": len(sel), "apex_found": found, "false": false,
                     "n_traces": survey.n_traces, "host": labels.get("host") or survey.metadata.get("scene", {})
                     .get("medium", {}).get("kind")})
        if log:
            log(f"  record {k}: {len(vis)} true, {len(sel)} detected, {found} apexes found, {false} false")
    m = coco_metrics(gts, dboxes, dscores)
    named = sorted({k for g in gkinds for k in g})
    kinds = getattr(detector, "kinds", None)
    if kinds and named and set(named) <= set(kinds):  # class-averaged over the kinds the records hold
        m["by_kind"] = coco_metrics(gts, kboxes, kscores, gt_kinds=gkinds, det_kinds=kkinds, kinds=kinds)
        m["by_kind"]["kinds"] = named
        m["by_kind_top"] = coco_metrics(gts, dboxes, dscores, gt_kinds=gkinds, det_kinds=dkinds, kinds=kinds)
        m["by_kind_top"]["kinds"] = named
    m.update({"apex_recall": found_total / max(true_total, 1), "false_per_true": false_total / max(true_total, 1),
              "n_records": len(rows), "n_true": true_total, "s_per_window": t_windows / max(n_windows, 1),
              "score_threshold": score_threshold, "rows": rows,
              "apex_recall_by_kind": {k: {"found": f, "n": n, "recall": f / n} for k, (f, n) in sorted(by_kind.items())}})
    return m
