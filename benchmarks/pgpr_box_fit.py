"""How the shipped detector's boxes sit against P-GPR's labels: size ratios and offsets per radar and split.

    python benchmarks/pgpr_box_fit.py [--pgpr DIR] [--out benchmarks/results]

Each label is matched one-to-one to a detection (IoU >= 0.5, score >= 0.5, best score first:
``box_matches``); for the matched pairs the table gives the median label/box width and height
ratios (with their spread) and the median offsets of the centre, top and bottom in box sizes.
A systematic ratio or offset is what a per-dataset box conversion could correct; scatter is not.
Writes ``pgpr_box_fit.md`` in ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402
from eval_pgpr import PGPR_DEFAULT, pgpr_records  # noqa: E402


def matched_pairs(det, records):
    """``[(label box, detection box)]`` in traces and samples, for the labels a detection matches."""
    from gpr3d.detection.evaluate import box_matches

    out = []
    for survey, lab in records:
        res = det.detect(survey, score_threshold=0.5)
        px = np.array([1.0, 1 / survey.dt_s, 1.0, 1 / survey.dt_s])
        truth = [np.asarray(x["box"]) * px for x in lab["labels"]]
        boxes = [np.asarray(t["box"]) * px for t in res["targets"]]
        if not boxes:
            continue
        hits = box_matches(truth, [x["kind"] for x in lab["labels"]], boxes, [t["kind"] for t in res["targets"]],
                           [t["score"] for t in res["targets"]])
        out += [(t, boxes[h[0]]) for t, h in zip(truth, hits) if h is not None]
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    from gpr3d.detection.infer import load_detector

    det = load_detector()
    lines = [f"Shipped detector vs P-GPR labels, pairs matched at IoU 0.5 (score >= 0.5); host CPU {cpu_name()}", "",
             "| radar | split | pairs | label/box width | label/box height | centre offset / width | "
             "top offset / height | bottom offset / height |", "|---|---|---|---|---|---|---|---|"]
    for radar in ("AIR", "IECAS"):
        for split in ("train", "val"):
            pairs = matched_pairs(det, pgpr_records(args.pgpr, split, f"{radar}_*"))
            lab, box = (np.array([x[i] for x in pairs]).reshape(-1, 4) for i in (0, 1))
            lw, lh = lab[:, 2] - lab[:, 0], lab[:, 3] - lab[:, 1]
            bw, bh = box[:, 2] - box[:, 0], box[:, 3] - box[:, 1]
            rw, rh = lw / bw, lh / bh
            cx = ((lab[:, 0] + lab[:, 2]) - (box[:, 0] + box[:, 2])) / 2 / bw
            top, bot = (lab[:, 1] - box[:, 1]) / bh, (lab[:, 3] - box[:, 3]) / bh
            lines.append(f"| {radar} | {split} | {len(pairs)} | {np.median(rw):.2f} +- {np.std(rw):.2f} | "
                         f"{np.median(rh):.2f} +- {np.std(rh):.2f} | {np.median(cx):+.3f} | "
                         f"{np.median(top):+.3f} +- {np.std(top):.3f} | {np.median(bot):+.3f} +- {np.std(bot):.3f} |")
            print(lines[-1], flush=True)
    write_table(args.out, "pgpr_box_fit.md", "\n".join(lines), "pgpr_box_fit.py", argv)


if __name__ == "__main__":
    main()
