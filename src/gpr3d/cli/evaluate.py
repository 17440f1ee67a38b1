"""``gpr3d eval``: evaluate the detector (COCO metrics) or the depth estimates on held-out B-scans."""

from __future__ import annotations

from pathlib import Path

from gpr3d.cli._common import _detector, _read_labels, add_detector_args, add_label_args, add_view_args
from gpr3d.core.errors import GPR3DError


def _eval_records(args):
    """The labelled records ``gpr3d eval`` judges on, and their description (checked before any model loads)."""
    if args.n is not None and args.n < 1:
        raise GPR3DError(f"--n must be at least 1, got {args.n}")
    if args.seed < 0:
        raise GPR3DError(f"--seed must be 0 or more, got {args.seed}")
    if getattr(args, "labels", None) is not None:
        if args.data is not None:
            raise GPR3DError("give --data or --labels, not both")
        recs = _read_labels(args, args.labels, args.split)
        recs = recs[: args.n] if args.n else recs
        return recs, f"{args.labels} ({len(recs)} labelled B-scans)"
    if args.data is not None:
        from gpr3d.io.packed import PackedDataset, labelled_records

        src = Path(args.data)
        if not src.exists():
            raise GPR3DError(f"--data {src}: no such file or folder")
        if src.is_file():
            PackedDataset(src)  # a wrong file fails here, in one line, before the model loads
        elif not (src / "samples").is_dir():
            raise GPR3DError(f"--data {src}: neither a packed dataset nor a gpr3d simulate folder (no samples/)")
        return labelled_records(src, n=args.n), f"{src} ({'first ' + str(args.n) if args.n else 'all'} records)"
    from gpr3d.simulation.surveys import survey_sample

    n = args.n or 60
    return (survey_sample(args.seed, i) for i in range(n)), f"held-out survey-scale forward-model set (seed {args.seed})"


NAME = "eval"
HELP = "evaluate the detector (COCO metrics) or the depth estimates on held-out B-scans"
EPILOG = ("examples:\n  gpr3d eval detector --n 60 --seed 777\n  gpr3d eval detector --data datasets/gprmax_survey.h5\n"
             "  gpr3d eval depth --data datasets/gprmax_survey.h5      (DepthNet, fit and hybrid)\n"
             "the full tables: python benchmarks/eval_detector.py WEIGHTS.pt ...; python benchmarks/eval_depth.py")


def add_arguments(sp):
    sp.add_argument("what", choices=("detector", "depth"), help="what to evaluate")
    sp.add_argument("--depthnet", default=None, help="depth: DepthNet weights (default: the shipped ones)")
    sp.add_argument("--n", type=int, default=None, help="records (default: 60 drawn, or all of --data)")
    sp.add_argument("--seed", type=int, default=777, help="seed of the held-out set (training uses 1000)")
    sp.add_argument("--data", default=None,
                    help="evaluate on a labelled dataset instead: packed file or gpr3d simulate folder "
                         "(e.g. datasets/gprmax_survey.h5)")
    sp.add_argument("--labels", default=None,
                    help="evaluate on labelled B-scans: a YOLO dataset, COCO .json or Pascal VOC .xml "
                         "(e.g. pgpr_1600MHz/val with --pixel-map s_per_px=3.125e-11 --class-names steel,pipe "
                         "--class-kinds pipe=pvc_pipe)")
    sp.add_argument("--split", default="val", choices=("train", "val", "test"),
                    help="the split of a YOLO data.yaml to evaluate on (default val)")
    add_label_args(sp)
    add_detector_args(sp)
    add_view_args(sp)


def run(args):
    records, what = _eval_records(args)
    if args.what == "depth":
        from gpr3d.inversion.depthnet import DepthEstimator
        from gpr3d.inversion.evaluate import depth_rows, depth_table

        est = DepthEstimator.load(args.depthnet, device=args.device)
        rows = depth_rows(records, estimator=est)
        print(f"{what}: {len({r['record'] for r in rows})} records, labelled boxes")
        print("\n".join(depth_table(rows)))
        return 0
    from gpr3d.detection.evaluate import evaluate_detector

    det = _detector(args)
    m = evaluate_detector(det, records, score_threshold=args.score)
    print(f"{what}: {m['n_records']} records, {m['n_true']} targets")
    print("| mAP@0.75 | mAP@0.5 | AR@10 | AR@100 | apex recall | false / true | s per window |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {m['mAP@0.75']:.3f} | {m['mAP@0.5']:.3f} | {m['AR@10']:.3f} | {m['AR@100']:.3f} | "
          f"{m['apex_recall']:.3f} | {m['false_per_true']:.3f} | {m['s_per_window']:.3f} |")
    print(f"class-agnostic: mAP@[.5:.95] {m['mAP']:.3f}, recall@0.5 {m['recall@0.5']:.3f}")
    if "by_kind" in m:
        k = m["by_kind"]
        print(f"class-averaged ({', '.join(k['kinds'])}): mAP@0.5 {k['mAP@0.5']:.3f}, mAP@0.75 {k['mAP@0.75']:.3f}, "
              f"mAP@[.5:.95] {k['mAP']:.3f}, AR@100 {k['AR@100']:.3f}, recall@0.5 {k['recall@0.5']:.3f}")
    print("apex recall by kind: " + ", ".join(f"{k} {v['recall']:.2f} ({v['found']}/{v['n']})"
                                              for k, v in m["apex_recall_by_kind"].items()))
    return 0
