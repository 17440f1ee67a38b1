"""Detectors on real labelled B-scans: P-GPR's 1.6 GHz validation split (and a device-held-out view).

    python benchmarks/eval_pgpr.py default [WEIGHTS.pt | runs/X/checkpoint.pt ...] [--pgpr DIR] [--out benchmarks/results]

P-GPR (Yue, Qin, Zhu, Ye, Wang, CIKM '26; CC BY 4.0) labels hyperbolas in real B-scans of
walls: ``steel`` (rebar) and ``pipe`` (PPR water pipes and PVC conduits: gpr3d's
``pvc_pipe``). Each PNG is read as a picture record (one trace per column, 256 rows =
8 ns, 1.6 GHz) and detected as any recording would be (``Detector.detect``: windows,
merge, apexes); boxes are compared in traces and seconds by pycocotools.

Rows per detector: class-agnostic (every box one class) and class-averaged (the mean
over rebar and pvc_pipe, for detectors that name kinds: each box stands under every kind
at its score times that kind's share, as multi-class detectors are scored; and, on the
whole set, under its best kind alone, as tables before 2026-12-06 gave it) mAP@0.5,
mAP@0.75, mAP@[.5:.95], AR@10, AR@100 and recall@0.5 (any score, 100 detections), on
``val`` and on each radar's files of ``val`` alone (``AIR_``, ``IECAS_``).
The published baselines on P-GPR's test split (pretrained backbones) are reference rows;
the test split itself is kept apart from the project. Writes ``pgpr.md`` beside ``--out``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402

PGPR_DEFAULT = ROOT.parent / "shared" / "data" / "real" / "pgpr_1600MHz"
#: P-GPR's own reading: classes 0 steel, 1 pipe; 256 rows = 8 ns; two 1.6 GHz radars
PGPR = dict(names=["steel", "pipe"], kinds="pipe=pvc_pipe", pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9)
#: the dataset paper's figures on its test split, class-averaged (mAP@0.5, mAP@[.5:.95], recall)
PUBLISHED = [("Faster R-CNN (pretrained, published)", 0.917, 0.507, 0.968), ("YOLOv8n (pretrained, published)", 0.919,
             0.497, None), ("RetinaNet (pretrained, published)", 0.889, 0.499, None),
             ("RT-DETR-L (pretrained, published)", 0.509, 0.265, None)]


def pgpr_records(folder, split: str = "val", only: str | None = None):
    """P-GPR's records of ``split`` (``"train,val"``: both), those named by the glob ``only`` alone if given."""
    from gpr3d.io.yolo import read_yolo

    return [r for part in split.split(",") for r in read_yolo(Path(folder) / part, pattern=only, **PGPR)]


def load(spec):
    """A detector from ``default``, a weights ``.pt``, an ``.onnx`` or a training ``checkpoint.pt``."""
    from gpr3d.detection.infer import Detector, load_detector

    if spec == "default":
        return load_detector(refiner="none"), "shipped default"
    p = Path(spec)
    if p.name.startswith("checkpoint"):
        import torch

        from gpr3d.core.training import read_checkpoint
        from gpr3d.detection.models import build_model
        from gpr3d.detection.windows import WindowConfig

        ck = read_checkpoint(p, "cpu")
        cfg = ck["config"]
        kinds = cfg.get("kinds")
        model = build_model(cfg["model"], image_size=cfg["window"]["rows"], kinds=kinds)
        model.load_state_dict(ck["model"])
        model.gpr3d_kinds = kinds
        model.eval()
        torch.set_grad_enabled(False)
        return Detector(model, WindowConfig(**cfg["window"])), f"{p.parent.name} step {ck['step']}"
    return load_detector(p, refiner="none"), p.name


def evaluate(det, records):
    from gpr3d.detection.evaluate import evaluate_detector

    t0 = time.perf_counter()
    m = evaluate_detector(det, records)
    m["wall_s"] = time.perf_counter() - t0
    return m


def worst_cases(det, recs, k: int, folder: Path) -> list[str]:
    """Overlays of the ``k`` records with the most labels missed at IoU 0.5 (score >= 0.5), and a line each."""
    import numpy as np

    from gpr3d.detection.evaluate import box_matches
    from gpr3d.viz.bscan import save_bscan_png

    rows = []
    for survey, lab in recs:
        res = det.detect(survey, score_threshold=0.5)
        px = np.array([1.0, 1 / survey.dt_s, 1.0, 1 / survey.dt_s])
        truth = lab["labels"]
        hits = box_matches([np.asarray(x["box"]) * px for x in truth], [x["kind"] for x in truth],
                           [np.asarray(t["box"]) * px for t in res["targets"]], [t["kind"] for t in res["targets"]],
                           [t["score"] for t in res["targets"]])
        missed = [x["kind"] for x, h in zip(truth, hits) if h is None]
        wrong = sum(bool(h) and not h[2] for h in hits)
        false = len(res["targets"]) - sum(h is not None for h in hits)
        rows.append((len(missed), false, wrong, missed, survey, lab, res))
    rows.sort(key=lambda r: (-r[0], -r[1]))
    folder.mkdir(parents=True, exist_ok=True)
    out = [f"Worst {k} B-scans (most labels missed at IoU 0.5, score >= 0.5), overlays in "
           f"{folder.relative_to(ROOT) if folder.is_relative_to(ROOT) else folder}:"]
    for n_miss, false, wrong, missed, survey, lab, res in rows[:k]:
        name = Path(lab["image"]).stem
        save_bscan_png(survey, folder / f"worst_{name}.png", cmap="gray", boxes=[t["box"] for t in res["targets"]],
                       box_labels=[f"{t['kind']} {t['score']:.2f}" for t in res["targets"]],
                       truth_boxes=[x["box"] for x in lab["labels"]],
                       title=f"{name} (P-GPR val): {n_miss} of {len(lab['labels'])} labels missed, {false} false, "
                             f"{wrong} of the wrong kind; labels dashed")
        kinds = ", ".join(f"{missed.count(m)} {m}" for m in sorted(set(missed))) or "none"
        out.append(f"- {name}: {n_miss} of {len(lab['labels'])} missed ({kinds}), {false} false boxes, {wrong} found "
                   f"with the wrong kind (`worst_{name}.png`)")
    return out


def _row(name, what, m):
    return (f"| {name} | {what} | {m['mAP@0.5']:.3f} | {m['mAP@0.75']:.3f} | {m['mAP']:.3f} | {m['AR@10']:.3f} | "
            f"{m['AR@100']:.3f} | {m['recall@0.5']:.3f} |")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("detectors", nargs="+", help="default, weights .pt/.onnx, or a training checkpoint.pt")
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (train/ and val/)")
    p.add_argument("--split", default="val", help="val (default), train, or train,val")
    p.add_argument("--only", default=None, help="these pictures only (a glob, e.g. IECAS_* for one radar's)")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default="pgpr.md", help="the result file's name in --out")
    p.add_argument("--refiner", nargs="*", default=[], help="box refiners (.pt/.onnx; 'default': the shipped one): "
                   "each detector is measured without a refiner, then with each")
    p.add_argument("--quality-weights", nargs="+", default=["own"], metavar="W",
                   help="a refiner with a quality head is measured with each of these weights on the scores "
                        "(0: the network's scores; own, the default: the weight the refiner gives each rule)")
    p.add_argument("--worst", type=int, default=0, help="overlays of the K B-scans with the most missed labels "
                   "(first detector), into --figures")
    p.add_argument("--figures", default=str(ROOT / "docs" / "figures" / "pgpr"))
    p.add_argument("--trace-scales", default="1", help="test-time views: the pictures also detected stretched along "
                   "their traces by these factors (comma-separated, e.g. 0.5,1,2), the boxes fused")
    p.add_argument("--mirror", action="store_true", help="test-time views: also each picture's traces reversed")
    p.add_argument("--vote", action="store_true", help="a fused box's score: the views' scores summed over the views")
    p.add_argument("--no-average", action="store_true", help="fused views keep the best box's corners (not the mean)")
    p.add_argument("--members", nargs="+", default=[], metavar="WEIGHTS",
                   help="an ensemble: these detectors' networks run on the same windows beside each detector's, "
                        "their boxes fused as views (Detector.set_members; with --vote a box scores its group's mean)")
    p.add_argument("--reference-from", default=None, metavar="GLOB",
                   help="with --trace-scales auto: the median trace width (gpr3d.detection.windows.trace_width) "
                        "of P-GPR's train pictures named by GLOB (the detector's training pictures)")
    args = p.parse_args(argv)
    try:
        scales = tuple(v if v == "auto" else float(v) for v in args.trace_scales.split(","))
        if not all(v == "auto" or 0.25 <= v <= 4 for v in scales):
            raise ValueError
    except ValueError:
        p.error(f"--trace-scales must be numbers in 0.25..4 or auto, separated by commas, got {args.trace_scales!r}")
    from gpr3d.core.errors import FormatError, GPR3DError

    for part in args.split.split(","):  # before any work: a folder that is not there is one line
        if not (Path(args.pgpr) / part).is_dir():
            p.error(f"--pgpr {args.pgpr}: no {part}/ folder in it (P-GPR's train/ and val/)")
    reference = None
    try:
        if args.reference_from:
            import numpy as np

            from gpr3d.detection.windows import WindowConfig, prepare, trace_width

            reference = float(np.median([trace_width(prepare(s, WindowConfig()))
                                         for s, _ in pgpr_records(args.pgpr, "train", args.reference_from)]))
            print(f"reference width {reference:.2f} traces (train {args.reference_from})", flush=True)
        recs = pgpr_records(args.pgpr, args.split, args.only)
    except FormatError as exc:  # (read_yolo: no picture, or none the glob names)
        p.error(str(exc))
    devices = {dev: [r for r in recs if Path(r[1]["image"]).name.startswith(dev + "_")] for dev in ("AIR", "IECAS")}
    devices = {d: v for d, v in devices.items() if v and len(v) < len(recs)}
    n_boxes = sum(len(r[1]["labels"]) for r in recs)
    what = f"{args.split}" + (f" {args.only}" if args.only else "")
    lines = [f"P-GPR {what}: {len(recs)} real 1.6 GHz B-scans, {n_boxes} labelled hyperbolas "
             f"({', '.join(f'{d} {len(v)}' for d, v in devices.items()) or 'one radar'}); host CPU {cpu_name()}, "
             "torch threads as set by the environment", "",
             "| detector | set, metric kind | mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@10 | AR@100 | recall@0.5 |",
             "|---|---|---|---|---|---|---|---|"]
    timing = []
    from refiner_variants import refiner_variants

    try:
        variants = refiner_variants(args.refiner, args.quality_weights)
    except GPR3DError as exc:
        p.error(str(exc))
    try:  # the members read before any work: a file that is not a detector is one line
        members = [load(m)[0] for m in args.members]
    except GPR3DError as exc:
        p.error(f"--members: {exc}")
    for spec, (refiner, qw) in [(d, r) for d in args.detectors for r in [(None, None), *variants]]:
        det, name = load(spec)
        det.refiner = None
        det.trace_scales, det.mirror, det.fuse_average, det.vote = scales, args.mirror, not args.no_average, args.vote
        if members:
            try:
                det.set_members(members)
            except GPR3DError as exc:
                p.error(f"--members: {exc}")
            name += (" + " + " + ".join(Path(m).parent.name if Path(m).name == "weights.pt" else m for m in args.members)
                     + (" (vote)" if args.vote and scales == (1.0,) and not args.mirror else "")
                     + (" (best box)" if args.no_average and scales == (1.0,) and not args.mirror else ""))
        if reference is not None:  # else what the weights recorded (finetune_pgpr.py), if they did
            det.reference_width = reference
        if "auto" in scales and not det.reference_width:
            p.error(f"--trace-scales auto: {spec} records no trace width; give --reference-from GLOB (the pictures "
                    "it was trained on)")
        if scales != (1.0,) or args.mirror:
            name += f" (views: x{', x'.join(str(v) if v == 'auto' else f'{v:g}' for v in scales)}{', mirrored' if args.mirror else ''}" + \
                (", best box" if args.no_average else "") + (", vote" if args.vote else "") + ")"
        if refiner:
            from gpr3d.detection.refine import load_refiner

            det.refiner = load_refiner(None if refiner == "default" else refiner, quality_weight=qw)
            name += f" + refiner {'shipped' if refiner == 'default' else Path(refiner).name}"
            if det.refiner.quality:
                name += " (its own quality weights)" if qw is None else f" (quality weight {qw:g})"
        for part, sub in [(what, recs)] + [(f"{what} {d} only", v) for d, v in devices.items()]:
            m = evaluate(det, sub)
            lines.append(_row(name, f"{part}, class-agnostic", m))
            if "by_kind" in m:
                lines.append(_row(name, f"{part}, class-averaged ({', '.join(m['by_kind']['kinds'])})",
                                  m["by_kind"]))
                if part == what:  # (as tables before 2026-12-06 gave it)
                    lines.append(_row(name, f"{part}, class-averaged, each box under its best kind alone",
                                      m["by_kind_top"]))
            if part == what:
                timing.append(f"{name}: {m['s_per_window'] * 1e3:.0f} ms per window, {m['wall_s']:.0f} s for the set")
            print(lines[-1], flush=True)
        if args.worst and spec == args.detectors[0] and (refiner, qw) == ([(None, None), *variants][-1]):
            lines += ["", *worst_cases(det, recs, args.worst, Path(args.figures)), ""]
    for name, m50, m, rec in PUBLISHED:
        lines.append(f"| {name} | P-GPR test, class-averaged | {m50:.3f} | - | {m:.3f} | - | - | "
                     f"{'-' if rec is None else f'{rec:.3f}'} |")
    lines += ["", "CPU time: " + "; ".join(timing)]
    write_table(args.out, args.name, "\n".join(lines), "eval_pgpr.py", argv)


if __name__ == "__main__":
    main()
