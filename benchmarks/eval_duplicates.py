"""Boxes the refiner moved onto one hyperbola: kept as they are, scored lower (the shipped rule), or removed.

    python benchmarks/eval_duplicates.py [--pgpr P-GPR_FOLDER] [--set datasets/gprmax_survey.h5]
        [--ious 0.5,0.6,0.7,0.8] [--out DIR] [--name soft_duplicates.md]

The shipped detector and refiner (the pair ``gpr3d detect`` uses) find every box of P-GPR's validation pictures and
of three simulated sets once, at score 0 and with refined boxes keeping their scores (``Detector.duplicate_iou =
None``): the held-out gprMax survey set (``--set``), the last 60 records of ``datasets/gprmax400.h5`` (held out of
every training) and 60 synthetic survey records (``survey_sample(777, i)``, as ``eval_detector.py --sets survey``).
Each rule below is then applied to those boxes alone, and the boxes scored as ``benchmarks/eval_pgpr.py``
(class-averaged over P-GPR's kinds) and ``benchmarks/eval_detector.py`` (apex recall and false targets per true one
at score 0.5) score them:

* ``kept``: the refined boxes as they are (what ``gpr3d detect`` did before ``soften_duplicates``);
* ``soft, IoU t``: ``gpr3d.detection.windows.soften_duplicates`` at overlap ``t``: a box that overlaps a surer one
  by ``t`` or more has its score multiplied by one minus that overlap (``t = 0.5``, the merge's own overlap, is the
  shipped rule, ``DUPLICATE_IOU``);
* ``removed, IoU t``: such a box dropped (greedy non-maximum suppression, ``fuse_views(average=False)``).

Both sets are ones no model trains on; the shipped overlap was not chosen on them alone (it is the merge's), and
the rows at other overlaps show how flat the choice is.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402
from eval_pgpr import PGPR_DEFAULT, load, pgpr_records  # noqa: E402


class Replay:
    """A stand-in detector that gives back results found before, in order (for ``evaluate_detector``)."""

    def __init__(self, kinds, results):
        self.kinds, self._results = kinds, iter(results)

    def detect(self, survey, *, score_threshold: float = 0.5):
        return next(self._results)


def apply(rule: str, iou: float | None, result: dict) -> dict:
    """``result`` (the detect contract, every box) with the rule applied to its targets' scores or list."""
    from gpr3d.detection.windows import fuse_views, soften_duplicates

    tg = result["targets"]
    if rule == "kept" or not tg:
        return result
    boxes = [t["box"] for t in tg]
    scores = [t["score"] for t in tg]
    if rule == "soft":
        new = soften_duplicates(boxes, scores, result["dt_s"], iou=iou)
        tg = [{**t, "score": float(s)} for t, s in zip(tg, new)]
    else:
        keep, _ = fuse_views(boxes, scores, result["dt_s"], iou=iou, average=False)
        tg = [tg[i] for i in sorted(keep)]
    return {**result, "targets": tg}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (its val/ split is used)")
    p.add_argument("--set", default=str(ROOT / "datasets" / "gprmax_survey.h5"), help="the held-out gprMax set")
    p.add_argument("--ious", default="0.5,0.6,0.7,0.8", help="overlaps tried, separated by commas (each in 0..1)")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "intel"))
    p.add_argument("--name", default="soft_duplicates.md")
    args = p.parse_args(argv)
    try:
        ious = [float(v) for v in args.ious.split(",")]
        if not ious or not all(0.0 < v <= 1.0 for v in ious):
            raise ValueError
    except ValueError:
        p.error(f"--ious must be numbers in (0, 1], separated by commas, got {args.ious!r}")
    if not (Path(args.pgpr) / "val").is_dir():
        p.error(f"--pgpr {args.pgpr}: no val/ folder in it (P-GPR's validation split)")
    if not Path(args.set).is_file():
        p.error(f"--set {args.set}: no such file")
    if Path(args.name).name != args.name or not args.name.endswith(".md"):
        p.error(f"--name {args.name}: a file name ending in .md (no folder: --out says where)")
    if not Path(args.out).is_dir():
        p.error(f"--out {args.out}: not a folder")
    from gpr3d.detection.evaluate import evaluate_detector
    from gpr3d.detection.refine import load_refiner
    from gpr3d.io.packed import labelled_records

    det, _ = load("default")
    det.refiner = load_refiner(None)
    det.duplicate_iou = None  # every refined box keeps its score: the rules are applied below
    t0 = time.perf_counter()
    from gpr3d.simulation.surveys import survey_sample

    simulated = {Path(args.set).name: lambda: labelled_records(args.set),
                 "gprmax400.h5, last 60": lambda: labelled_records(ROOT / "datasets" / "gprmax400.h5", n=60, last=True),
                 "survey_sample(777, i < 60)": lambda: (survey_sample(777, i) for i in range(60))}
    sets = {}
    for name, records in [("P-GPR val", lambda: pgpr_records(args.pgpr, "val")), *simulated.items()]:
        records = list(records())
        sets[name] = (records, [det.detect(s, score_threshold=0.0) for s, _ in records])
        print(f"{name}: {len(records)} records detected ({time.perf_counter() - t0:.0f} s)", flush=True)
    rules = [("kept", None)] + [("soft", v) for v in ious] + [("removed", v) for v in ious]
    pg = ["| refined boxes that overlap a surer one | P-GPR val class-averaged mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | "
          "AR@100 | recall@0.5 | class-agnostic mAP@0.5 |", "|---|---|---|---|---|---|---|"]
    sim = ["| refined boxes that overlap a surer one | set | mAP@0.75 | mAP@0.5 | AR@100 | apex recall | "
           "false per true |", "|---|---|---|---|---|---|---|"]
    for rule, iou in rules:
        label = "kept" if rule == "kept" else f"{rule}, IoU >= {iou:g}" + (" (shipped)" if rule == "soft" and
                                                                           iou == 0.5 else "")
        for name, (records, results) in sets.items():
            m = evaluate_detector(Replay(det.kinds, [apply(rule, iou, r) for r in results]), records)
            if name == "P-GPR val":
                k = m["by_kind"]
                pg.append(f"| {label} | {k['mAP@0.5']:.3f} | {k['mAP@0.75']:.3f} | {k['mAP']:.3f} | "
                          f"{k['AR@100']:.3f} | {k['recall@0.5']:.3f} | {m['mAP@0.5']:.3f} |")
            else:
                sim.append(f"| {label} | {name} | {m['mAP@0.75']:.3f} | {m['mAP@0.5']:.3f} | {m['AR@100']:.3f} | "
                           f"{m['apex_recall']:.3f} | {m['false_per_true']:.3f} |")
        print(pg[-1], flush=True)
    head = (f"The shipped detector and refiner ({det.provenance.get('name', 'default')}, "
            f"{det.refiner.provenance.get('name', 'refiner')}) on P-GPR val ({len(sets['P-GPR val'][0])} real "
            f"B-scans) and three simulated sets no model trains on; each rule applied to the same refined boxes; host "
            f"CPU {cpu_name()}, detection {time.perf_counter() - t0:.0f} s")
    text = "\n".join([head, "", *pg, "", "Simulated sets (score 0.5 for apex recall and false targets):", "", *sim])
    write_table(Path(args.out), args.name, text, "eval_duplicates.py", argv)


if __name__ == "__main__":
    main()
