"""Train the box refiner (``gpr3d.detection.refine``) on labelled records, on the CPU, in minutes.

    python references/detection/train_refiner.py --out runs/refiner.pt [--pgpr DIR] [--only GLOB] [--synthetic N]
        [--wall N] [--gprmax FILE.h5[:N] ...] [--epochs 9] [--per-label 24] [--onnx OUT.onnx]

Labels from P-GPR's train split (its own box rule: the people who labelled its real
B-scans) and, with ``--synthetic N`` / ``--gprmax``, from N survey-scale synthetic records
(``survey_sample(1000, i)``, the detector's training source), with ``--wall N`` from N handheld
wall scans (``profile="wall"``: with ``--pgpr none`` a refiner that has read no real label) and packed gprMax records
(each ``FILE:N`` leaves out its last N; several files may be given): gpr3d's label rule
(``docs/labels.md``). Each record is rendered as the shipped detector's windows render it. Nothing of P-GPR's validation
split nor of the held-out gprMax survey set is read.

P-GPR: Yue, Qin, Zhu, Ye, Wang, "P-GPR: a Ground Penetrating Radar Dataset for Pipeline
Detection", CIKM '26; CC BY 4.0. A refiner trained on it carries that credit in its provenance.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
from eval_pgpr import PGPR_DEFAULT, pgpr_records  # noqa: E402

from finetune_pgpr import PGPR_CREDIT  # noqa: E402  (beside this file)


def samples(records, window, whole: bool = False, head: int = 0):
    """``(image, label boxes px, whole boxes px or None, head)`` of each record, rendered as the detector's windows
    are; with ``whole``, records whose labels name their apexes (simulated ones) and hold a box cut by the record's
    first or last trace give their whole boxes (``gpr3d.detection.refine.whole_boxes``), the others None."""
    from gpr3d.detection.refine import record_image, record_pixmap, whole_boxes
    from gpr3d.detection.windows import prepare

    for survey, lab in records:
        pm = record_pixmap(survey, window.rows)
        vis = [x for x in lab["labels"] if x.get("visible", True)]
        boxes = np.asarray([pm.box_to_px(x["box"]) for x in vis], float).reshape(-1, 4)
        image = record_image(prepare(survey, window), window.style)
        if whole and vis and all("apex_trace" in x for x in vis):
            wb = whole_boxes([x["box"] for x in vis], [x["apex_trace"] for x in vis], survey.n_traces)
            wpx = np.asarray([pm.box_to_px(b) for b in wb], float).reshape(-1, 4)
            if not np.array_equal(wpx, boxes):
                yield image, boxes, wpx, head
                continue
        yield image, boxes, None, head


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="the refiner's weights (.pt)")
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (its train/ is read); 'none' for none")
    p.add_argument("--only", default=None, help="P-GPR train pictures named by this glob only (AIR_* for one radar: "
                   "a refiner for the device-held-out test)")
    p.add_argument("--synthetic", type=int, default=0, help="survey-scale synthetic records (seed 1000) to add")
    p.add_argument("--wall", type=int, default=0, metavar="N",
                   help="handheld wall scans (survey_sample(1000, i, profile='wall'), seed 1000) to add: with "
                        "--pgpr none, a refiner that has read no real label (the zero-shot line)")
    p.add_argument("--gprmax", nargs="+", default=[], metavar="FILE[:N]",
                   help="packed gprMax files to add, FILE:N leaving out its last N")
    p.add_argument("--name", default="gpr3d box refiner", help="the refiner's name in detections")
    p.add_argument("--epochs", type=int, default=9)
    p.add_argument("--per-label", type=int, default=24)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--whole", action="store_true",
                   help="simulated labels cut by the record's ends taught as the whole hyperbola's box (reaching past "
                        "the record), whose centre is the apex: gpr3d.detection.refine.whole_boxes")
    p.add_argument("--rule-heads", action="store_true",
                   help="one head a label rule whose data are given: P-GPR's pictures teach the 'pgpr' head, the "
                        "synthetic and gprMax records the 'gpr3d' head (gpr3d detect picks the head by its input: "
                        "pgpr for pictures)")
    p.add_argument("--quality", type=int, default=0, metavar="N",
                   help="also learn each box's IoU with its label (a quality head that rescales the detector's "
                        "scores) from N boxes a label drawn wider and N a label anywhere in the picture")
    p.add_argument("--quality-weights", nargs="+", default=[], metavar="RULE=W",
                   help="with --quality: the weight of the quality on the scores for each rule's head, recorded in "
                        "the weights (gpr3d detect's default; 1 for a rule not named); the shipped refiner: "
                        "gpr3d=1 pgpr=0 (benchmarks/results/intel/refiner_rules_quality.md)")
    p.add_argument("--members", type=int, default=1,
                   help="train this many networks (seeds --seed, --seed + 1, ...) on boxes drawn anew for each, and "
                        "write them as one refiner that averages their moves")
    p.add_argument("--jitter-scale", type=float, default=1.0,
                   help="the training boxes' spread about each label times this (JITTER): 0.5 trains a fine stage, "
                        "applied after the first refiner (gpr3d.detection.refine.FINE_JITTER_SCALE)")
    p.add_argument("--onnx", default=None, help="also export the refiner (crops in, edge moves out) to this .onnx")
    args = p.parse_args(argv)
    if args.synthetic < 0 or args.wall < 0:
        p.error(f"--synthetic and --wall are counts of records (whole numbers >= 0), got {args.synthetic} and "
                f"{args.wall}")
    if args.pgpr == "none" and not args.synthetic and not args.wall and not args.gprmax:
        p.error("nothing to train on: --pgpr none with none of --synthetic, --wall and --gprmax")
    if args.members < 1:
        p.error(f"--members must be a whole number >= 1, got {args.members}")
    if not 0.0 < args.jitter_scale <= 4.0:
        p.error(f"--jitter-scale must be a number in (0, 4], got {args.jitter_scale}")
    if args.quality < 0:
        p.error(f"--quality must be a whole number >= 0, got {args.quality}")
    from gpr3d.detection.refine import RULES

    quality_weights = {}
    for spec in args.quality_weights:
        rule, _, w = spec.partition("=")
        try:
            quality_weights[rule] = float(w)
        except ValueError:
            quality_weights[rule] = -1.0
        if rule not in RULES or not 0.0 <= quality_weights[rule] <= 8.0:
            p.error(f"--quality-weights {spec}: a rule ({', '.join(RULES)}) = a number in 0..8")
    if quality_weights and not args.quality:
        p.error("--quality-weights weigh a quality head: give --quality N too")
    for spec in args.gprmax:  # checked before any work: a wrong one is one line
        path, _, held = spec.partition(":")
        if not Path(path).is_file():
            p.error(f"--gprmax {spec}: no such file")
        if held and not held.isdigit():
            p.error(f"--gprmax {spec}: N after the colon is the count of records left out, a whole number")
    import torch

    from gpr3d.detection.refine import build_refiner, export_refiner_onnx, save_refiner, train_refiner
    from gpr3d.detection.weights import load_weights

    _, window, _ = load_weights()
    # with --rule-heads, a head for each rule whose data are given: P-GPR's pictures teach 'pgpr', records 'gpr3d'
    rules = [r for r in RULES if (r == "pgpr" and args.pgpr != "none") or
             (r == "gpr3d" and (args.synthetic or args.wall or args.gprmax))] if args.rule_heads else None
    pgpr_head = rules.index("pgpr") if rules and "pgpr" in rules else 0
    gpr3d_head = rules.index("gpr3d") if rules and "gpr3d" in rules else 0
    pictures, records, parts = [], [], []
    if args.pgpr != "none":
        from gpr3d.core.errors import FormatError

        try:
            recs = pgpr_records(args.pgpr, "train", args.only)
        except FormatError as exc:  # (read_yolo: a folder with no picture, or none that the glob names)
            p.error(f"--only {args.only!r}: no P-GPR train picture matches" if args.only else str(exc))
        pictures += recs
        parts.append(f"P-GPR train{f' {args.only}' if args.only else ''} ({len(recs)} B-scans)")
    if args.synthetic:
        from gpr3d.simulation.surveys import survey_sample

        records += [survey_sample(1000, i) for i in range(args.synthetic)]
        parts.append(f"survey_sample(1000, i < {args.synthetic})")
    if args.wall:
        from gpr3d.simulation.surveys import survey_sample

        records += [survey_sample(1000, i, profile="wall") for i in range(args.wall)]
        parts.append(f"survey_sample(1000, i < {args.wall}, profile='wall')")
    for spec in args.gprmax:
        from gpr3d.io.packed import labelled_records

        path, _, held = spec.partition(":")
        recs = list(labelled_records(path))
        recs = recs[: len(recs) - int(held)] if held else recs
        records += recs
        parts.append(f"{Path(path).name} ({len(recs)} records{f', its last {held} left out' if held else ''})")
    t0, cpu0 = time.perf_counter(), time.process_time()
    from itertools import chain

    nets = []
    for k in range(args.members):  # each member on boxes drawn anew (its own seed)
        if args.members > 1:
            print(f"member {k + 1}/{args.members}", flush=True)
        data = chain(samples(pictures, window, args.whole, pgpr_head), samples(records, window, args.whole, gpr3d_head))
        nets.append(train_refiner(data, epochs=args.epochs, per_label=args.per_label, seed=args.seed + k,
                                  heads=len(rules) if rules else 1, quality=args.quality,
                                  jitter_scale=args.jitter_scale, log=lambda m: print(m, flush=True)))
    net = nets[0]
    if args.members > 1:
        net = build_refiner(len(rules) if rules else 1, bool(args.quality), args.members)
        for member, trained in zip(net.members, nets):
            member.load_state_dict(trained.state_dict())
        net.eval()
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    prov = {"name": args.name, "command": "python references/detection/train_refiner.py " + " ".join(argv or sys.argv[1:]),
            "data": " + ".join(parts), "whole": args.whole, "epochs": args.epochs,
            **({"rules": rules} if rules else {}),
            **({"quality": True, "quality_boxes": args.quality} if args.quality else {}),
            **({"quality_weights": quality_weights} if quality_weights else {}),
            "per_label": args.per_label, "seed": args.seed,
            **({"jitter_scale": args.jitter_scale} if args.jitter_scale != 1.0 else {}),
            **({"members": args.members} if args.members > 1 else {}),
            "train_wall_s": round(wall, 1), "train_cpu_s": round(cpu, 1), "torch_threads": torch.get_num_threads(),
            "host": platform.processor() or platform.machine()}
    if args.pgpr != "none":
        prov["credit"] = PGPR_CREDIT
    save_refiner(net, args.out, provenance=prov)
    print(f"wrote {args.out}: {wall:.0f} s wall, {cpu:.0f} s CPU")
    if args.onnx:
        r = export_refiner_onnx(args.out, args.onnx)
        q = "" if r["max_quality_diff"] is None else f", of its qualities {r['max_quality_diff']:.2e}"
        print(f"wrote {r['file']} ({r['bytes']} bytes), largest difference of its moves from PyTorch's "
              f"{r['max_abs_diff']:.2e}{q}")


if __name__ == "__main__":
    from gpr3d.core.errors import GPR3DError

    try:
        main()
    except GPR3DError as e:  # a file that is not what it should be (not a packed dataset, no labels): one line
        sys.exit(f"train_refiner.py: {e}")
