"""Where a detector loses on P-GPR validation: its metrics with one error removed at a time by an oracle (issue 29).

    python benchmarks/pgpr_oracles.py [default | WEIGHTS.pt ...] [--pgpr DIR] [--refiner default|none|FILE]

The detector's boxes on P-GPR's validation split (as ``eval_pgpr.py`` reads it) are scored by
pycocotools as they are, then with one kind of error taken away by the labels themselves:

- *kinds*: each box takes the kind of the label it overlaps most (IoU > 0.3);
- *scores*: a box that matches a label at IoU 0.5 ranks above every one that does not; *scores = IoU*
  and *score x IoU*: each box ranked by its IoU with the nearest label (what a perfect localisation
  quality head would give), alone or times its score;
- *drop duplicates / poor boxes / background*: the boxes that a greedy match (best score first)
  finds to be a second box on a label already taken, a box on a label at IoU 0.1-0.5, or a box on no
  label, scored 0;
- *boxes snapped*: each box at IoU >= 0.5 with a label moved onto it (the ceiling of box refinement).

With ``--proxies`` it also ranks the boxes by what the shipped refiner can tell of its own boxes at no cost
(score x q^a, a in 0.5..4): *mirror agreement*, the IoU of the moves it predicts for a box and for its mirror
image (first or last pass); *moved*, the IoU of the network's box with the refined one; *converged*, of the
last two passes' boxes; and their Spearman correlation with the true IoU of the boxes that match a label.

Each row says how far its error caps the class-averaged metric; a second table gives the edge errors of
the matched boxes (each label with its best box at IoU >= 0.5), in shares of the label's width and
height, per radar. Writes ``pgpr_oracles.md`` in ``--out``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402
from eval_pgpr import PGPR_DEFAULT, pgpr_records  # noqa: E402


def _iou(a, b):
    import numpy as np
    import torch
    from torchvision.ops import box_iou

    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    return box_iou(torch.as_tensor(a, dtype=torch.float64), torch.as_tensor(b, dtype=torch.float64)).numpy()


def _with_proxies(det, survey):
    """The refined boxes of ``survey`` (record units, clipped), their scores, kinds and the refiner's own quality
    proxies (see the module's text), as ``Detector.detect`` would place them."""
    import numpy as np

    from gpr3d.detection.refine import apply_deltas, mirror_deltas, pair_iou, record_image, record_pixmap

    _, proc, boxes, scores, labels, *_ = det._views(survey)
    ref, pm = det.refiner, record_pixmap(survey, det.window.rows)
    head = ref.head_for(survey)[0]
    moves = slice(head * (4 + int(ref.quality)), head * (4 + int(ref.quality)) + 4)  # its head's edge moves
    image = np.ascontiguousarray(record_image(proc, det.window.style)[None], dtype=np.float32)
    mirrored, w = np.ascontiguousarray(image[..., ::-1]), image.shape[-1]
    steps = [np.array([pm.box_to_px(b) for b in np.asarray(boxes, float).reshape(-1, 4)]).reshape(-1, 4)]
    agree = []
    for _ in range(ref.passes if len(steps[0]) else 0):
        at = np.ascontiguousarray(steps[-1], dtype=np.float32)
        direct = np.asarray(ref.predict(image, at), float)[:, moves]
        flip = np.ascontiguousarray(np.stack([w - at[:, 2], at[:, 1], w - at[:, 0], at[:, 3]], axis=1))
        back = mirror_deltas(np.asarray(ref.predict(mirrored, flip), float)[:, moves])
        agree.append(pair_iou(apply_deltas(steps[-1], direct), apply_deltas(steps[-1], back)))
        steps.append(apply_deltas(steps[-1], 0.5 * (direct + back)))
    final = np.array([pm.px_to_box(b) for b in steps[-1]]).reshape(-1, 4)
    t_end = (survey.n_samples - 1) * survey.dt_s
    final[:, [0, 2]] = np.clip(final[:, [0, 2]], 0, survey.n_traces - 1)
    final[:, [1, 3]] = np.clip(final[:, [1, 3]], 0, t_end)
    ok = (final[:, 2] > final[:, 0]) & (final[:, 3] > final[:, 1])
    none = np.zeros(len(final))
    q = {"mirror agreement, first pass": agree[0] if agree else none,
         "mirror agreement, last pass": agree[-1] if agree else none,
         "moved (network box vs refined)": pair_iou(steps[0], steps[-1]) if agree else none,
         "converged (last two passes)": pair_iou(steps[-2], steps[-1]) if agree else none}
    kinds = [det.kinds[int(k) - 1] if det.kinds else "target" for k in np.asarray(labels)]
    return final[ok], np.asarray(scores, float)[ok], [k for k, o in zip(kinds, ok) if o], {k: v[ok] for k, v in q.items()}


def collect(det, records, proxies: bool = False):
    """Per record: label boxes and kinds, detected boxes, scores and kinds, all in (trace, sample) units (and the
    refiner's quality proxies with ``proxies``)."""
    import numpy as np

    out = []
    for survey, lab in records:
        px = np.array([1.0, 1 / survey.dt_s, 1.0, 1 / survey.dt_s])
        if proxies:
            db, ds, dk, q = _with_proxies(det, survey)
        else:
            tg = det.detect(survey, score_threshold=0.0)["targets"]
            db, ds, dk, q = [t["box"] for t in tg], [t["score"] for t in tg], [t["kind"] for t in tg], None
        out.append(dict(name=Path(lab["image"]).stem,
                        gt=np.asarray([x["box"] for x in lab["labels"]], float).reshape(-1, 4) * px,
                        gk=[x["kind"] for x in lab["labels"]], db=np.asarray(db, float).reshape(-1, 4) * px,
                        ds=np.asarray(ds, float), dk=list(dk), q=q))
    return out


def proxy_rows(R, kinds):
    """Rows for the refiner's quality proxies: the metrics with scores x q^a and q's rank correlation with IoU."""
    import numpy as np
    from scipy.stats import spearmanr

    from gpr3d.detection.evaluate import coco_metrics

    G, GK, D, DK = [r["gt"] for r in R], [r["gk"] for r in R], [r["db"] for r in R], [r["dk"] for r in R]
    true_iou = [_iou(r["db"], r["gt"]).max(1) if len(r["gt"]) else np.zeros(len(r["db"])) for r in R]
    on = np.concatenate([(t >= 0.5) & (r["ds"] >= 0.3) for t, r in zip(true_iou, R)])
    t_all = np.concatenate(true_iou)
    rows = [f"| score itself | {spearmanr(np.concatenate([r['ds'] for r in R])[on], t_all[on])[0]:.3f} | - | - | - | - |"]
    for key in R[0]["q"]:
        q_all = np.concatenate([r["q"][key] for r in R])
        cells = []
        for a in (0.5, 1.0, 2.0, 4.0):
            m = coco_metrics(G, D, [r["ds"] * r["q"][key] ** a for r in R], gt_kinds=GK, det_kinds=DK, kinds=kinds)
            cells.append(f"{m['mAP@0.5']:.3f} / {m['mAP@0.75']:.3f} / {m['mAP']:.3f}")
        rows.append(f"| {key} | {spearmanr(q_all[on], t_all[on])[0]:.3f} | " + " | ".join(cells) + " |")
    return rows


def greedy_classes(gt, db, ds):
    """Each detection's class in a greedy match, best score first: tp, dup, poor (IoU 0.1-0.5) or bg."""
    import numpy as np

    iou = _iou(db, gt)
    cls = [""] * len(db)
    taken = set()
    for i in np.argsort(-ds, kind="stable"):
        if not iou.shape[1]:
            cls[i] = "bg"
            continue
        j = int(iou[i].argmax())
        q = iou[i, j]
        if q >= 0.5 and j not in taken:
            cls[i] = "tp"
            taken.add(j)
        else:
            cls[i] = "dup" if q >= 0.5 else "poor" if q >= 0.1 else "bg"
    return cls


def oracle_rows(R, kinds):
    """(name, metrics) for the detector as it is and with each oracle."""
    import numpy as np

    from gpr3d.detection.evaluate import coco_metrics

    G, GK = [r["gt"] for r in R], [r["gk"] for r in R]

    def score(D=None, S=None, DK=None):
        return coco_metrics(G, D or [r["db"] for r in R], S or [r["ds"] for r in R], gt_kinds=GK,
                            det_kinds=DK or [r["dk"] for r in R], kinds=kinds)

    best = [_iou(r["db"], r["gt"]) for r in R]  # detections x labels
    q = [b.max(1) if b.shape[1] else np.zeros(len(b)) for b in best]
    cls = [greedy_classes(r["gt"], r["db"], r["ds"]) for r in R]
    rows = [("as it is", score())]
    okinds = [[r["gk"][j] if b.shape[1] and b[i, j] > 0.3 else k for i, (j, k) in
               enumerate(zip(b.argmax(1) if b.shape[1] else [0] * len(b), r["dk"]))] for r, b in zip(R, best)]
    rows.append(("kinds from the labels", score(DK=okinds)))
    rows.append(("scores: matches at IoU 0.5 first", score(S=[r["ds"] + (qq >= 0.5) for r, qq in zip(R, q)])))
    rows.append(("scores = IoU with the nearest label", score(S=q)))
    rows.append(("scores = score x IoU", score(S=[r["ds"] * qq for r, qq in zip(R, q)])))
    for what, drop in [("duplicates", {"dup"}), ("poor boxes (IoU 0.1-0.5)", {"poor"}), ("background", {"bg"}),
                       ("all three", {"dup", "poor", "bg"})]:
        rows.append((f"drop {what}", score(S=[np.where([c in drop for c in cc], 0.0, r["ds"])
                                              for r, cc in zip(R, cls)])))
    snapped = []
    for r, b in zip(R, best):
        d = r["db"].copy()
        if b.shape[1]:
            sel = b.max(1) >= 0.5
            d[sel] = r["gt"][b.argmax(1)[sel]]
        snapped.append(d)
    rows.append(("boxes at IoU >= 0.5 snapped onto their labels", score(D=snapped)))
    counts = {c: sum(cc.count(c) for cc in cls) for c in ("tp", "dup", "poor", "bg")}
    above = {c: sum(sum(1 for k, s in zip(cc, r["ds"]) if k == c and s >= 0.5) for cc, r in zip(cls, R))
             for c in ("tp", "dup", "poor", "bg")}
    return rows, counts, above


def edge_rows(R):
    """Edge errors of each label's best box at IoU >= 0.5, in shares of the label's width and height."""
    import numpy as np

    err, dev = [], []
    for r in R:
        b = _iou(r["gt"], r["db"])
        for a in range(b.shape[0]):
            if not b.shape[1] or b[a].max() < 0.5:
                continue
            d, g = r["db"][b[a].argmax()], r["gt"][a]
            w, h = g[2] - g[0], g[3] - g[1]
            err.append([(d[0] - g[0]) / w, (d[1] - g[1]) / h, (d[2] - g[2]) / w, (d[3] - g[3]) / h, b[a].max()])
            dev.append(r["name"].split("_")[0])
    err, dev = np.array(err), np.array(dev)
    out = []
    for name in ["all", *sorted(set(dev))]:
        e = err if name == "all" else err[dev == name]
        mu, sd = e[:, :4].mean(0), e[:, :4].std(0)
        out.append(f"| {name} | {len(e)} | " + " | ".join(f"{m:+.3f} / {s:.3f}" for m, s in zip(mu, sd)) +
                   f" | {np.median(e[:, 4]):.3f} | {(e[:, 4] >= 0.75).mean():.3f} |")
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("detector", nargs="?", default="default", help="default (the shipped one) or weights .pt/.onnx")
    p.add_argument("--refiner", default="auto", help="auto (the shipped refiner with the shipped detector), none, "
                   "or a refiner file")
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (train/ and val/)")
    p.add_argument("--split", default="val")
    p.add_argument("--proxies", action="store_true", help="also rank by the refiner's own quality proxies")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    if not (Path(args.pgpr) / args.split).is_dir():
        p.error(f"--pgpr: no {args.split}/ folder in {args.pgpr}")
    if args.detector != "default" and not Path(args.detector).is_file():
        p.error(f"detector: no such file {args.detector}")
    from gpr3d.detection.infer import load_detector

    det = load_detector(None if args.detector == "default" else args.detector, refiner=args.refiner)
    if args.proxies and det.refiner is None:
        p.error("--proxies needs a refiner (--refiner auto with the shipped detector, or a refiner file)")
    t0 = time.perf_counter()
    R = collect(det, pgpr_records(args.pgpr, args.split), proxies=args.proxies)
    wall = time.perf_counter() - t0
    named = sorted({k for r in R for k in r["gk"]})
    rows, counts, above = oracle_rows(R, list(det.kinds))
    base = rows[0][1]
    lines = [f"P-GPR {args.split}: {len(R)} real B-scans, {sum(len(r['gt']) for r in R)} labels; detector "
             f"{args.detector}, refiner {args.refiner}; class-averaged over {', '.join(named)}; host CPU "
             f"{cpu_name()}, detection {wall:.0f} s", "",
             "| oracle | mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@100 | recall@0.5 | mAP@[.5:.95] gained |",
             "|---|---|---|---|---|---|---|"]
    for name, m in rows:
        lines.append(f"| {name} | {m['mAP@0.5']:.3f} | {m['mAP@0.75']:.3f} | {m['mAP']:.3f} | {m['AR@100']:.3f} | "
                     f"{m['recall@0.5']:.3f} | {m['mAP'] - base['mAP']:+.3f} |")
    lines += ["", "Detections by greedy match (best score first): " +
              ", ".join(f"{c} {counts[c]} ({above[c]} at score >= 0.5)" for c in counts), "",
              "Edge errors of each label's best box at IoU >= 0.5 (box minus label; mean / std, shares of the "
              "label's width for x, height for t):", "",
              "| radar | matched | left | top | right | bottom | median IoU | IoU >= 0.75 |", "|---|---|---|---|---|---|---|---|",
              *edge_rows(R)]
    if args.proxies:
        lines += ["", "Scores x q^a with the refiner's own quality proxies q (class-averaged mAP@0.5 / mAP@0.75 / "
                  "mAP@[.5:.95]; rho: Spearman correlation of q with the true IoU of the boxes at IoU >= 0.5 and "
                  "score >= 0.3):", "", "| proxy q | rho | a = 0.5 | a = 1 | a = 2 | a = 4 |", "|---|---|---|---|---|---|",
                  *proxy_rows(R, list(det.kinds))]
    write_table(args.out, "pgpr_oracles.md", "\n".join(lines), "pgpr_oracles.py", argv)


if __name__ == "__main__":
    main()
