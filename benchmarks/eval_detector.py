"""Detector evaluation table (the reference's Table 1 format) on held-out records.

    python benchmarks/eval_detector.py WEIGHTS.pt|default [MORE.pt ...] [--n 60] [--seed 777] [--runtime onnx]

Sets (no training or tuning touches them):
* ``survey``: survey-scale forward-model B-scans ``survey_sample(seed, i)``, i < n
  (training uses seed 1000), with the recording artefacts switched on;
* ``gprmax400``: the last n stored gprMax B-scans (``datasets/gprmax400.h5``; short
  scenes, other physics; training with ``--packed`` keeps the last 60 out) when present;
* ``gprmax_survey``: the held-out gprMax set at survey scale (``--gprmax-survey``, default
  ``datasets/gprmax_survey.h5``; ``gpr3d simulate --preset survey --seed 4242``), all its
  records, when present. Nothing trains or tunes on it.

Prints a Markdown table per set and writes ``detector_eval.md`` / ``.csv`` (``--name``) beside
``--out``, with training time (from the weights' provenance) and CPU time per window.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402


def records(kind: str, n: int, seed: int, gprmax_survey=None):
    from gpr3d.io.packed import labelled_records

    if kind == "survey":
        from gpr3d.simulation.surveys import survey_sample

        for i in range(n):
            yield survey_sample(seed, i)
    elif kind == "gprmax_survey":
        yield from labelled_records(gprmax_survey)
    else:
        yield from labelled_records(ROOT / "datasets" / "gprmax400.h5", n=n, last=True)


def draw_worst(det, per_record, args, kind):
    from gpr3d.viz.bscan import save_bscan_png

    order = sorted(per_record, key=lambda r: (r["apex_found"] - r["false"]) / max(r["n_true"], 1))
    out = ROOT / "docs" / "figures" / "detections"
    out.mkdir(parents=True, exist_ok=True)
    worst = {r["record"] for r in order[: args.worst]}
    for k, (s, lab) in enumerate(records(kind, args.n, args.seed, args.gprmax_survey)):
        if k not in worst:
            continue
        r = next(x for x in per_record if x["record"] == k)
        res = det.detect(s, score_threshold=args.score)
        vis = [x for x in lab["labels"] if x["visible"]]
        name = f"worst_survey_{args.seed}_{k}.png" if kind == "survey" else f"worst_{kind}_{k}.png"
        save_bscan_png(s.dewow().remove_background(), out / name,
                       cmap="gray", boxes=[t["box"] for t in res["targets"]] + [x["box"] for x in vis],
                       apexes=[(t["apex_trace"], t["apex_time_s"]) for t in res["targets"]],
                       title=f"{kind} record {k}: {r['apex_found']}/{r['n_true']} apexes found, "
                             f"{r['false']} false (boxes: detections first, then truth)")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("weights", nargs="+")
    p.add_argument("--n", type=int, default=60)
    p.add_argument("--seed", type=int, default=777)
    p.add_argument("--sets", nargs="+", default=["survey", "gprmax400", "gprmax_survey"])
    p.add_argument("--gprmax-survey", default=str(ROOT / "datasets" / "gprmax_survey.h5"),
                   help="the held-out gprMax survey set: packed file or gpr3d simulate folder")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--runtime", default="torch", choices=("auto", "torch", "onnx"),
                   help="torch (default) or onnx ('default' weights only: the shipped export)")
    p.add_argument("--refiner", nargs="*", default=[], help="box refiners (.pt/.onnx; 'default': the shipped one): "
                   "each detector is measured without a refiner, then with each")
    p.add_argument("--quality-weights", nargs="+", default=["own"], metavar="W",
                   help="a refiner with a quality head is measured with each of these weights on the scores "
                        "(0: the network's scores; own, the default: the weight the refiner gives each rule)")
    p.add_argument("--score", type=float, default=0.5, help="score threshold for apex recall / false targets")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default="detector_eval", help="the result files' name in --out (.md and .csv)")
    p.add_argument("--worst", type=int, default=0, help="draw the K records of the survey and gprmax_survey sets "
                   "with the lowest apex recall (first weights) into docs/figures/detections/worst_*.png")
    p.add_argument("--mirror", action="store_true", help="test-time views: each record also with its traces "
                   "reversed, the boxes fused (Detector.mirror)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    from gpr3d.detection.evaluate import evaluate_detector
    from gpr3d.detection.infer import load_detector
    from gpr3d.detection.models import count_parameters

    from refiner_variants import refiner_variants

    from gpr3d.core.errors import GPR3DError

    try:
        variants = refiner_variants(args.refiner, args.quality_weights)
    except GPR3DError as exc:
        p.error(str(exc))
    rows = []
    for w, (refiner, qw) in [(w, r) for w in args.weights for r in [(None, None), *variants]]:
        det = load_detector(None if w == "default" else w, engine=args.runtime, refiner="none")
        det.refiner = None
        prov = det.provenance
        name = prov.get("name", Path(w).stem)
        if args.mirror:
            det.mirror = True
            name += " (mirrored too)"
        if refiner:
            from gpr3d.detection.refine import load_refiner

            det.refiner = load_refiner(None if refiner == "default" else refiner, quality_weight=qw)
            name += f" + refiner {'shipped' if refiner == 'default' else Path(refiner).name}"
            if det.refiner.quality:
                name += " (its own quality weights)" if qw is None else f" (quality weight {qw:g})"
        for kind in args.sets:
            if kind == "gprmax400" and not (ROOT / "datasets" / "gprmax400.h5").exists():
                continue
            if kind == "gprmax_survey" and not Path(args.gprmax_survey).exists():
                print(f"no {args.gprmax_survey}: gprmax_survey set skipped", file=sys.stderr)
                continue
            t = time.perf_counter()
            m = evaluate_detector(det, records(kind, args.n, args.seed, args.gprmax_survey),
                                  score_threshold=args.score)
            rows.append({"model": name, "set": kind, "records": m["n_records"],
                         "true_targets": m["n_true"], "mAP@0.5": m["mAP@0.5"], "mAP@0.75": m["mAP@0.75"],
                         "AR@10": m["AR@10"], "AR@100": m["AR@100"], "apex_recall": m["apex_recall"],
                         "false_per_true": m["false_per_true"], "cpu_s_per_window": m["s_per_window"],
                         "train_steps": prov.get("steps_done", prov.get("config", {}).get("steps")),
                         "train_s": prov.get("train_wall_s"), "train_device": prov.get("device"),
                         "params_M": count_parameters(det.model) / 1e6 if det.model is not None else None,
                         "eval_wall_s": time.perf_counter() - t,
                         "apex_recall_by_kind": " ".join(f"{k}:{v['recall']:.2f}({v['n']})"
                                                         for k, v in m["apex_recall_by_kind"].items())})
            print(json.dumps(rows[-1]), flush=True)
            if args.worst and kind in ("survey", "gprmax_survey") and w == args.weights[0] and refiner is None:
                draw_worst(det, m["rows"], args, kind)
    head = ["model", "set", "records", "true_targets", "mAP@0.75", "mAP@0.5", "AR@10", "AR@100", "apex_recall",
            "false_per_true", "apex_recall_by_kind", "cpu_s_per_window", "params_M", "train_steps", "train_s",
            "train_device"]
    lines = [f"Host CPU: {cpu_name()}, {args.threads} threads; score threshold {args.score} for apex recall; "
             f"survey set seed {args.seed}, n {args.n}", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = []
        for h in head:
            v = r.get(h)
            cells.append(f"{v:.3f}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    out = Path(args.out)
    write_table(out, f"{args.name}.md", "\n".join(lines), "eval_detector.py", argv)
    with open(out / f"{args.name}.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(rows[0].keys()) if rows else head)
        wr.writeheader()
        wr.writerows(rows)


if __name__ == "__main__":
    main()
