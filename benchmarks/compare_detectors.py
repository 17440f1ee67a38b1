"""The detector comparison table (the reference's Table 1 format) from dumped detections.

Training and the GPU runs happen on a machine with an accelerator:

    PYTHONPATH=src python references/detection/train_many.py --device cuda --out /tmp/peers --batch 16 \
        --workers 15 --max-seconds 36 --plan frcnn_lean:300 frcnn_r18:300 frcnn_r50:300 frcnn_r101:300 \
        frcnn_mobilenet:300 retinanet_r18:300 fcos_r18:300 ssdlite:300
    PYTHONPATH=src python references/detection/dump_detections.py peers_dets.json /tmp/peers/*.pt

then, here (the held-out survey-scale set: survey_sample(777, i), i < 30):

    python benchmarks/compare_detectors.py peers_dets.json [--out benchmarks/results]

CPU time per window is measured here for each architecture (2 threads, 20 windows).
"""

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np
import torch

from gpr3d.detection.evaluate import apex_matches, coco_metrics
from gpr3d.detection.models import build_model, count_parameters
from gpr3d.io.coco import BOX_PAD_PERIODS
from gpr3d.simulation.surveys import survey_sample

ROOT = Path(__file__).resolve().parents[1]


def cpu_window_s(name, n=20):
    m = build_model(name).eval()
    x = [torch.rand(3, 256, 256)]
    with torch.inference_mode():
        m(x)
        t = time.perf_counter()
        for _ in range(n):
            m(x)
    return (time.perf_counter() - t) / n


def main():
    p = argparse.ArgumentParser()
    p.add_argument("dets")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--score", type=float, default=0.5)
    args = p.parse_args()
    torch.set_num_threads(2)
    d = json.loads(Path(args.dets).read_text())
    n = len(next(iter(d.values()))["records"])
    recs = []
    for i in range(n):
        s, lab = survey_sample(777, i)
        recs.append({**lab, "frequency_hz": s.frequency_hz})
    rows = []
    for name, r in d.items():
        gts, db, ds = [], [], []
        found = true = false = 0
        for lab, res in zip(recs, r["records"]):
            vis = [x for x in lab["labels"] if x["visible"]]
            to_px = np.array([1, 1 / lab["dt_s"], 1, 1 / lab["dt_s"]])
            gts.append(np.asarray([x["box"] for x in vis], float).reshape(-1, 4) * to_px)
            db.append(np.asarray([t["box"] for t in res["targets"]], float).reshape(-1, 4) * to_px)
            ds.append(np.asarray([t["score"] for t in res["targets"]], float))
            sel = [t for t in res["targets"] if t["score"] >= args.score]
            quarter = 0.25 / lab["frequency_hz"]
            # the box rule's apex (centre trace, top + pad), the same for every model
            apex = [[0.5 * (t["box"][0] + t["box"][2]), t["box"][1] + BOX_PAD_PERIODS / lab["frequency_hz"]] for t in sel]
            a, b = apex_matches([[x["apex_trace"], x["apex_time_s"]] for x in vis], apex, [t["score"] for t in sel],
                                max_traces=3, max_s=quarter)
            found, true, false = found + a, true + len(vis), false + b
        m = coco_metrics(gts, db, ds)
        model = build_model(name)
        rows.append({"model": name, "mAP@0.75": m["mAP@0.75"], "mAP@0.5": m["mAP@0.5"], "AR@10": m["AR@10"],
                     "AR@100": m["AR@100"], "apex_recall": found / max(true, 1), "false_per_true": false / max(true, 1),
                     "params_M": count_parameters(model) / 1e6, "train_steps": r.get("steps"),
                     "train_s_gpu": r["provenance"].get("train_wall_s"), "cpu_s_per_window": cpu_window_s(name)})
        print(json.dumps(rows[-1]), flush=True)
    head = list(rows[0].keys())
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        lines.append("| " + " | ".join(f"{v:.3f}" if isinstance(v, float) else str(v) for v in r.values()) + " |")
    table = "\n".join(lines)
    print(table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "detector_comparison.md").write_text(table + "\n")
    with open(out / "detector_comparison.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=head)
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
