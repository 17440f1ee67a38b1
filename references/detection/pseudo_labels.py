"""Pseudo-labels for self-training without real labels: a detector's confident boxes on unlabelled pictures,
written as a YOLO dataset that ``finetune_pgpr.py --pgpr`` reads as it reads P-GPR.

    python references/detection/pseudo_labels.py runs/dh/zs_wide/weights.pt --out runs/dh/pseudo [--score 0.7]

The pictures of ``--pgpr``'s ``--split`` are read as pictures only: their label files are never opened (the
records are read from a copy of the image folder with no ``labels/``), so a model trained on the result has
seen no real label (issue 29 item 5: sim-to-real without labels). Each box at or above ``--score`` becomes a
label line: ``steel`` for the kinds of metal (rebar, steel_pipe) and a one-class detector's boxes, ``pipe`` for the
others (pvc_pipe, void, tank), P-GPR's two class names, so that the same reading (``names``, ``kinds``, pixel map) applies. The images in
``OUT/train/images`` are links to the originals.

``--drop-echoes``: a box lying under another box of the same or a higher score (the other's top higher by over
a third of its height, its bottom no lower, the two overlapping over half the narrower one's traces) is left
out: the parallel copies of a hyperbola that a wall scanner's ringing draws under each bar, which the zero-shot
model boxes (checked against P-GPR *train* labels, 2026-12-07: of the once self-trained zero-shot model's 1,515
boxes at score 0.7 the rule drops 280, of which 4 matched a label at IoU 0.5, and the share of its boxes that match
one rises from 0.378 to 0.461; the validation labels were not looked at).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
from eval_pgpr import PGPR, PGPR_DEFAULT, load  # noqa: E402

#: gpr3d kind -> P-GPR class id (0 steel, 1 pipe); any other name (a one-class detector's) is 0
CLASS_OF = {"rebar": 0, "steel_pipe": 0, "pvc_pipe": 1, "void": 1, "tank": 1}


def yolo_line(box, kind: str, n_traces: int, n_samples: int, dt_s: float) -> str:
    """One YOLO label line for a box ``[i0, t0, i1, t1]`` in traces and seconds on a picture of ``n_traces``
    columns and ``n_samples`` rows ``dt_s`` apart (the inverse of :func:`gpr3d.io.yolo.read_yolo`'s reading:
    a column's centre at pixel x + 0.5)."""
    i0, t0, i1, t1 = (float(v) for v in box)
    x0, x1 = (i0 + 0.5) / n_traces, (i1 + 0.5) / n_traces
    y0, y1 = (t0 / dt_s + 0.5) / n_samples, (t1 / dt_s + 0.5) / n_samples
    x0, y0, x1, y1 = max(x0, 0.0), max(y0, 0.0), min(x1, 1.0), min(y1, 1.0)
    return f"{CLASS_OF.get(kind, 0)} {(x0 + x1) / 2:.6f} {(y0 + y1) / 2:.6f} {x1 - x0:.6f} {y1 - y0:.6f}"


def under(box, other, overlap: float = 0.5) -> bool:
    """Whether ``box`` lies under ``other`` (both ``[i0, t0, i1, t1]``): their traces overlap over ``overlap`` of
    the narrower one's, ``other``'s top is higher by over 0.3 of its height, and its bottom is no lower."""
    width = min(box[2] - box[0], other[2] - other[0])
    shared = min(box[2], other[2]) - max(box[0], other[0])
    return (width > 0 and shared >= overlap * width and other[3] <= box[3]
            and box[1] - other[1] > 0.3 * (other[3] - other[1]))


def drop_echoes(targets: list) -> list:
    """``targets`` without those lying under another target of the same or a higher score (:func:`under`)."""
    return [t for t in targets if not any(o is not t and o["score"] >= t["score"] and under(t["box"], o["box"])
                                          for o in targets)]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("weights", help="the detector (a weights .pt, or 'default')")
    p.add_argument("--out", required=True, help="the pseudo-labelled dataset's folder (OUT/train/images, labels)")
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT))
    p.add_argument("--split", default="train")
    p.add_argument("--score", type=float, default=0.7, help="the boxes kept: score at or above this")
    p.add_argument("--drop-echoes", action="store_true", help="leave out boxes under a box of a higher score")
    args = p.parse_args(argv)
    if not 0.0 < args.score <= 1.0:
        p.error(f"--score must lie in (0, 1], got {args.score}")
    src = Path(args.pgpr) / args.split
    if not (src / "images").is_dir():
        p.error(f"--pgpr {args.pgpr} --split {args.split}: no {args.split}/images/ folder there")
    if args.weights != "default" and not Path(args.weights).is_file():
        p.error(f"no such weights file: {args.weights}")
    from gpr3d.io.yolo import read_yolo, yolo_images

    out = Path(args.out) / "train"
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    for img in yolo_images(src):  # the pictures alone: no labels/ beside these links
        link = out / "images" / img.name
        if not link.exists():
            link.symlink_to(img.resolve())
    blind = Path(args.out) / "_blind"  # the same links, no labels folder: what the detector reads
    (blind / "images").mkdir(parents=True, exist_ok=True)
    for img in yolo_images(out):
        if not (blind / "images" / img.name).exists():
            (blind / "images" / img.name).symlink_to(img.resolve())
    det, name = load(args.weights)
    n_boxes, kinds = 0, {}
    for survey, lab in read_yolo(blind, **PGPR):
        if lab["labels"]:  # (the blind folder has no labels/: this cannot happen unless someone put one there)
            raise SystemExit(f"pseudo_labels.py: {blind} holds labels; remove it and run again")
        res = det.detect(survey, score_threshold=args.score)
        targets = drop_echoes(res["targets"]) if args.drop_echoes else res["targets"]
        lines = [yolo_line(t["box"], t["kind"], survey.n_traces, survey.n_samples, survey.dt_s) for t in targets]
        for t in targets:
            kinds[t["kind"]] = kinds.get(t["kind"], 0) + 1
        n_boxes += len(lines)
        stem = Path(lab["image"]).stem
        (out / "labels" / f"{stem}.txt").write_text("".join(f"{ln}\n" for ln in lines))
    summary = {"detector": name, "weights": args.weights, "split": args.split, "score": args.score,
               "drop_echoes": args.drop_echoes,
               "pictures": len(yolo_images(out)), "boxes": n_boxes, "kinds": kinds}
    (Path(args.out) / "pseudo_labels.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    from gpr3d.core.errors import GPR3DError

    try:
        sys.exit(main())
    except GPR3DError as e:  # a damaged picture or weights file: one line, as the gpr3d commands answer
        sys.exit(f"pseudo_labels.py: {e}")
