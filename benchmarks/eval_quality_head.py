"""How well a box refiner's quality head ranks detections (issue 29): its predicted IoU, the detector's score and
their product against each box's true IoU with the nearest label, on P-GPR's real validation pictures and on the
held-out gprMax survey set.

    python benchmarks/eval_quality_head.py [--refiner default] [--sets pgpr gprmax_survey] [--out DIR]

Every box the shipped detector reports at score >= ``--score`` (default 0.05) is refined by the refiner (its head for
the record: P-GPR's for pictures, gpr3d's for recordings; the scores left as the network gives them), then its
quality is read where it ended (``BoxRefiner.quality_of``). Per set: Spearman's rank correlation of each ranking
with the true IoU (all boxes; boxes at IoU >= 0.5), and the area under the ROC curve of telling boxes at IoU >= 0.5
from the others and boxes at IoU >= 0.75 from the others (a ranking that puts every better box first: 1; chance: 0.5).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402


def boxes_of(det, records, score: float):
    """``(score, quality, true IoU)`` arrays over every box of ``records`` the detector reports at ``score``."""
    import numpy as np

    from gpr3d.detection.refine import best_iou, record_image, record_pixmap
    from gpr3d.detection.windows import prepare

    scores, quality, iou = [], [], []
    for survey, lab in records:
        res = det.detect(survey, score_threshold=score)
        if not res["targets"]:
            continue
        b = np.array([t["box"] for t in res["targets"]], float)
        image = record_image(prepare(survey, det.window), det.window.style)
        quality.append(det.refiner.quality_of(survey, det.window.rows, b, image))
        scores.append([t["score"] for t in res["targets"]])
        truth = [x["box"] for x in lab["labels"] if x.get("visible", True)]
        px = record_pixmap(survey, det.window.rows)  # IoU in the record's pixels: traces and rows alike
        iou.append(best_iou(np.array([px.box_to_px(x) for x in b]).reshape(-1, 4),
                            np.array([px.box_to_px(x) for x in truth]).reshape(-1, 4)))
    return np.concatenate(scores), np.concatenate(quality), np.concatenate(iou)


def auc(rank, positive) -> float:
    """Area under the ROC curve of ``rank`` telling ``positive`` from the rest (ties count half)."""
    from scipy.stats import rankdata

    r = rankdata(rank)
    n1 = int(positive.sum())
    n0 = len(rank) - n1
    if not n1 or not n0:
        return float("nan")
    return float((r[positive].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--refiner", default="default", help="a refiner with a quality head (.pt/.onnx; default: shipped)")
    p.add_argument("--sets", nargs="+", default=["pgpr", "gprmax_survey"], choices=("pgpr", "gprmax_survey"))
    p.add_argument("--score", type=float, default=0.05, help="boxes reported at this score and above")
    p.add_argument("--pgpr", default=str(ROOT.parent / "shared" / "data" / "real" / "pgpr_1600MHz"))
    p.add_argument("--gprmax-survey", default=str(ROOT / "datasets" / "gprmax_survey.h5"))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default="quality_head.md")
    args = p.parse_args(argv)
    if not 0.0 <= args.score <= 1.0:
        p.error(f"--score must lie in 0..1, got {args.score}")
    if args.refiner != "default" and not Path(args.refiner).is_file():
        p.error(f"--refiner {args.refiner}: no such file")
    if "pgpr" in args.sets and not (Path(args.pgpr) / "val").is_dir():
        p.error(f"--pgpr {args.pgpr}: no val/ folder in it")
    if "gprmax_survey" in args.sets and not Path(args.gprmax_survey).is_file():
        p.error(f"--gprmax-survey {args.gprmax_survey}: no such file")
    import numpy as np
    from scipy.stats import spearmanr

    from gpr3d.core.errors import GPR3DError
    from gpr3d.detection.infer import load_detector

    try:
        det = load_detector(engine="torch", refiner=args.refiner, quality_weight=0.0)
    except GPR3DError as exc:
        p.error(str(exc))
    if not det.refiner.quality:
        p.error(f"--refiner {args.refiner}: it has no quality head")
    lines = [f"Quality head of {det.refiner.provenance.get('name', args.refiner)} on the shipped detector's boxes "
             f"(score >= {args.score}, refined, scores as the network gives them); host CPU {cpu_name()}", "",
             "| set | head | boxes | at IoU >= 0.5 | ranking | Spearman with IoU, all | at IoU >= 0.5 | "
             "AUC IoU >= 0.5 | AUC IoU >= 0.75 |", "|---|---|---|---|---|---|---|---|---|"]
    for name in args.sets:
        t = time.perf_counter()
        if name == "pgpr":
            from eval_pgpr import pgpr_records

            recs, head = pgpr_records(args.pgpr, "val"), "pgpr"
        else:
            from gpr3d.io.packed import labelled_records

            recs, head = list(labelled_records(args.gprmax_survey)), "gpr3d"
        s, q, iou = boxes_of(det, recs, args.score)
        good = iou >= 0.5
        for what, rank in (("score", s), ("quality", q), ("score x quality", s * q)):
            lines.append(f"| {name} | {head} | {len(s)} | {int(good.sum())} | {what} | "
                         f"{spearmanr(rank, iou).statistic:.3f} | {spearmanr(rank[good], iou[good]).statistic:.3f} | "
                         f"{auc(rank, good):.3f} | {auc(rank, iou >= 0.75):.3f} |")
            print(lines[-1], flush=True)
        print(f"{name}: {time.perf_counter() - t:.0f} s", flush=True)
    write_table(args.out, args.name, "\n".join(lines), "eval_quality_head.py", argv)


if __name__ == "__main__":
    main()
