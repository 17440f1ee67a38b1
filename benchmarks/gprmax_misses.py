"""Where the shipped detector loses the held-out gprMax survey set's targets, and why.

    python benchmarks/gprmax_misses.py [--detector default|FILE.pt] [--refiner default|none|FILE] [--score 0.5]
        [--set FILE.h5] [--out DIR]

Every labelled target of the set (``datasets/gprmax_survey.h5``: gprMax 4 B-scans at survey scale, seed 4242,
never trained on) is put in groups by what it is and where it lies, and for each group the table gives:

* ``apex found``: the issue's apex recall (a detection at or above ``--score`` with its apex within 3 traces and a
  quarter period of the label's: ``gpr3d.detection.evaluate``);
* ``IoU >= 0.5`` / ``IoU >= 0.75``: some detection, at any score, overlaps the label's box that well (what the
  network sees at all, and how tightly);
* ``IoU >= 0.5, score >= --score``: found and sure of it;
* ``apex off``: of those, the share whose apex is more than 3 traces from the label's (the box is right, its apex
  is not);
* ``median score``: of the best-scored detection at IoU >= 0.5, zero where there is none.

The groups: the target kind; ``isolated`` / ``under a stronger echo`` (its apex lies inside the box of another
labelled target whose echo is at least as strong); ``whole`` / ``cut`` (its label box reaches the record's first or
last trace, so half of the hyperbola is missing and the apex comes from the box's height:
``gpr3d.detection.windows.apex_of_box``); and five bands of echo contrast (the envelope's peak within a period of
the apex, over the record's median envelope, both on the detector's own processed view). Nothing here changes
the detector; the figures say where to work next.

A second table puts the false targets (detections at or above ``--score`` whose apex matches no label's: the
issue's "false per true") where they lie: on a labelled target's box with the apex elsewhere, on a target
labelled not visible, under a labelled target (multiples, ringing), above every target (direct wave, surface) or
elsewhere (:func:`false_where`).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402

KINDS = ("rebar", "steel_pipe", "tank", "pvc_pipe", "void")


def false_where(t: dict, labels: list[dict], period: float) -> str:
    """Where a false target (a detection at or above the score whose apex matches no visible label's) lies, against
    the record's labels (traces and seconds): ``box right, apex off`` (its box overlaps a visible label's at IoU >=
    0.5), ``unlabelled target`` (the same against a label marked not visible), ``under a target`` (its apex lies
    within a visible label's traces and more than half a period later: a multiple or the target's own ringing),
    ``above every target`` (its apex more than a period earlier than every visible label's: direct wave, surface)
    or ``elsewhere``."""
    from gpr3d.detection.refine import pair_iou

    b = np.asarray(t["box"], float)
    vis = [x for x in labels if x.get("visible", True)]
    hidden = [x for x in labels if not x.get("visible", True)]

    def overlaps(group):
        if not group:
            return False
        scale = np.array([1.0, 1e9, 1.0, 1e9])  # (seconds as nanoseconds: IoU does not change)
        return bool((pair_iou(b * scale, np.array([x["box"] for x in group], float) * scale) >= 0.5).any())

    if overlaps(vis):
        return "box right, apex off"
    if overlaps(hidden):
        return "unlabelled target"
    if any(x["box"][0] <= t["apex_trace"] <= x["box"][2] and t["apex_time_s"] > x["apex_time_s"] + 0.5 * period
           for x in vis):
        return "under a target"
    if not vis or t["apex_time_s"] < min(x["apex_time_s"] for x in vis) - period:
        return "above every target"
    return "elsewhere"


FALSE_PLACES = ("box right, apex off", "unlabelled target", "under a target", "above every target", "elsewhere")


def target_rows(det, records, score: float, false: list | None = None) -> list[dict]:
    """One row per visible labelled target: its groups and what the detector made of it. With a list ``false``,
    each false target (score >= ``score``, apex matching no label's) is appended to it as ``(place, score)``
    (:func:`false_where`)."""
    from gpr3d.detection.evaluate import apex_matches
    from gpr3d.detection.refine import pair_iou
    from gpr3d.detection.windows import prepare, rows_interval
    from gpr3d.processing.analytic import hilbert_envelope

    rows = []
    for k, (survey, labels) in enumerate(records):
        vis = [x for x in labels["labels"] if x.get("visible", True)]
        found = det.detect(survey, score_threshold=0.0)["targets"]
        sure = [t for t in found if t["score"] >= score]
        period = 1.0 / (survey.frequency_hz or 1e9)
        _, _, hit = apex_matches([[x["apex_trace"], x["apex_time_s"]] for x in vis],
                                 [[t["apex_trace"], t["apex_time_s"]] for t in sure], [t["score"] for t in sure],
                                 max_traces=3.0, max_s=0.25 * period, return_found=True)
        if false is not None:  # which sure detections are false: greedy by score, so each one's turn decides
            order = np.argsort(-np.array([t["score"] for t in sure], float), kind="stable")
            trues = [[x["apex_trace"], x["apex_time_s"]] for x in vis]
            before = 0
            for n in range(1, len(order) + 1):
                sub = [sure[j] for j in order[:n]]
                _, now = apex_matches(trues, [[t["apex_trace"], t["apex_time_s"]] for t in sub],
                                      [t["score"] for t in sub], max_traces=3.0, max_s=0.25 * period)
                if now > before:
                    t = sure[order[n - 1]]
                    false.append((false_where(t, labels["labels"], period), float(t["score"])))
                before = now
        env = hilbert_envelope(prepare(survey, replace(det.window, equalise=False)).astype(np.float64), axis=1)
        spr, floor = rows_interval(survey, det.window), float(np.median(env)) + 1e-30
        half = max(1, int(round(0.5 * period / spr)))
        peaks = []
        for x in vis:
            tr, r = int(round(x["apex_trace"])), int(round(x["apex_time_s"] / spr))
            peaks.append(float(env[max(tr - 2, 0) : tr + 3, max(r - half, 0) : r + half + 1].max(initial=0.0)))
        to_px = np.array([1.0, 1.0 / survey.dt_s, 1.0, 1.0 / survey.dt_s])
        boxes = np.array([t["box"] for t in found], float).reshape(-1, 4) * to_px
        scores = np.array([t["score"] for t in found], float)
        for i, (x, h) in enumerate(zip(vis, hit)):
            b = np.asarray(x["box"], float)
            iou = pair_iou(b * to_px, boxes)  # (one label against every detection)
            good = iou >= 0.5
            best = int(np.argmax(np.where(good, scores, -1.0))) if good.any() else None
            masked = any(o["box"][0] <= x["apex_trace"] <= o["box"][2]
                         and o["box"][1] <= x["apex_time_s"] <= o["box"][3]
                         and peaks[j] >= peaks[i] for j, o in enumerate(vis) if j != i)
            rows.append({"record": k, "kind": x.get("kind", "target"), "found": bool(h),
                         "iou": float(iou.max(initial=0.0)), "score": float(scores[best]) if best is not None else 0.0,
                         "apex_off": (abs(found[best]["apex_trace"] - x["apex_trace"]) > 3.0) if best is not None
                         else None, "masked": masked, "cut": b[0] <= 0.5 or b[2] >= survey.n_traces - 1.5,
                         "contrast": peaks[i] / floor})
    return rows


def group_line(name: str, rows: list[dict], score: float) -> str:
    n = len(rows)
    if not n:
        return f"| {name} | 0 | - | - | - | - | - | - |"
    sure = [r for r in rows if r["iou"] >= 0.5 and r["score"] >= score]
    off = f"{np.mean([r['apex_off'] for r in sure]):.2f}" if sure else "-"
    return (f"| {name} | {n} | {np.mean([r['found'] for r in rows]):.2f}"
            f" | {np.mean([r['iou'] >= 0.5 for r in rows]):.2f}"
            f" | {np.mean([r['iou'] >= 0.75 for r in rows]):.2f} | {len(sure) / n:.2f} | {off}"
            f" | {np.median([r['score'] for r in rows]):.2f} |")


def table(rows: list[dict], score: float) -> list[str]:
    head = [f"| group | targets | apex found | IoU >= 0.5 | IoU >= 0.75 | IoU >= 0.5, score >= {score} | apex off "
            "(of those) | median score |", "|---|---|---|---|---|---|---|---|"]
    lines = head + [group_line("all", rows, score)]
    lines += [group_line(k, [r for r in rows if r["kind"] == k], score) for k in KINDS]
    lines += [group_line("isolated", [r for r in rows if not r["masked"]], score),
              group_line("under a stronger echo", [r for r in rows if r["masked"]], score)]
    for k in ("pvc_pipe", "void"):
        lines.append(group_line(f"{k}, isolated", [r for r in rows if r["kind"] == k and not r["masked"]], score))
    lines += [group_line("whole (box inside the record)", [r for r in rows if not r["cut"]], score),
              group_line("cut by the record's first or last trace", [r for r in rows if r["cut"]], score)]
    edges = np.quantile([r["contrast"] for r in rows], np.linspace(0, 1, 6))
    for a, b in zip(edges[:-1], edges[1:]):
        lines.append(group_line(f"contrast {a:.1f}-{b:.1f}", [r for r in rows if a <= r["contrast"] <= b], score))
    return lines


def false_table(false: list, n_true: int) -> list[str]:
    """Lines of the false targets' table: per place, how many, per true target, and their median score."""
    lines = ["| false target | count | per true target | median score |", "|---|---|---|---|"]
    for place in (*FALSE_PLACES, "all"):
        sc = [s for p, s in false if p == place or place == "all"]
        med = f"{np.median(sc):.2f}" if sc else "-"
        lines.append(f"| {place} | {len(sc)} | {len(sc) / max(n_true, 1):.3f} | {med} |")
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--set", default=str(ROOT / "datasets" / "gprmax_survey.h5"), help="the held-out packed set")
    p.add_argument("--detector", default="default", help="default (the shipped one) or a detector weights file (.pt)")
    p.add_argument("--refiner", default="default", help="default (the shipped one), none, or a refiner file")
    p.add_argument("--score", type=float, default=0.5, help="score threshold of 'found' (0..1)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default="gprmax_misses.md")
    args = p.parse_args(argv)
    if not 1 <= args.threads <= 256:
        p.error(f"--threads must lie in 1..256, got {args.threads}")
    if Path(args.name).name != args.name or not args.name.endswith(".md"):
        p.error(f"--name {args.name}: a file name ending in .md (no folder: --out says where)")
    if not 0.0 < args.score <= 1.0:
        p.error(f"--score must lie in (0, 1], got {args.score}")
    if not Path(args.set).is_file():
        p.error(f"--set {args.set}: no such file")
    if args.detector != "default" and not Path(args.detector).is_file():
        p.error(f"--detector {args.detector}: no such file (or default)")
    if args.refiner not in ("default", "none") and not Path(args.refiner).is_file():
        p.error(f"--refiner {args.refiner}: no such file (or default, none)")
    if not Path(args.out).is_dir():
        p.error(f"--out {args.out}: not a folder")
    import torch

    from gpr3d.detection.infer import load_detector
    from gpr3d.io.packed import labelled_records

    torch.set_num_threads(args.threads)
    from gpr3d.core.errors import GPR3DError

    try:  # a file that is not a detector's (or a refiner's) weights: one line, before any work
        det = load_detector(None if args.detector == "default" else args.detector, engine="torch",
                            refiner=args.refiner)
    except GPR3DError as exc:
        p.error(str(exc))
    t0 = time.perf_counter()
    false: list = []
    rows = target_rows(det, labelled_records(args.set), args.score, false)
    refiner = "no refiner" if det.refiner is None else f"refiner {det.refiner.provenance.get('name', args.refiner)}"
    who = "The shipped detector" if args.detector == "default" else f"The detector {args.detector}"
    text = "\n".join([f"{who} ({refiner}) on {Path(args.set).name}: {len(rows)} labelled targets in "
                      f"{len({r['record'] for r in rows})} records; host CPU {cpu_name()}, {args.threads} threads, "
                      f"{time.perf_counter() - t0:.0f} s", "", *table(rows, args.score), "",
                      f"False targets (score >= {args.score:g}, apex matching no label's), by where they lie:", "",
                      *false_table(false, len(rows))])
    write_table(Path(args.out), args.name, text, "gprmax_misses.py", argv)


if __name__ == "__main__":
    main()
