"""``gpr3d train``: train the hyperbola detector or DepthNet on survey-scale B-scans (resumable)."""

from __future__ import annotations

import sys
from pathlib import Path

from gpr3d.cli._common import _in_range, _names_list, _read_labels, _writable, add_label_args
from gpr3d.core.errors import GPR3DError


def _labels_provenance(labels) -> dict:
    """The user's label files (and the files they name) by SHA-256, for the weights' provenance."""
    if not labels:
        return {}
    import hashlib

    p = Path(labels)
    files = sorted(p.glob("*.xml")) if p.is_dir() else [p]
    return {"labels": str(p), "labels_sha256": {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in files}}


def cmd_train_depthnet(args):
    """``gpr3d train depthnet``: forward-model records (and packed gprMax ones) prepared once, then trained."""
    from dataclasses import asdict

    from gpr3d.inversion.depthnet import (
        DepthTrainConfig,
        cache_depth_records,
        load_depth_records,
        save_depthnet,
        train_depthnet,
        validate_depthnet,
    )
    from gpr3d.simulation.surveys import SurveySource

    if args.records < 1:
        raise GPR3DError(f"--records must be at least 1, got {args.records}")
    if args.augment or args.wall_fraction:
        raise GPR3DError(f"--{'augment' if args.augment else 'wall-fraction'} is for the detector; DepthNet trains "
                         "on its records as they are")
    if args.init == "default":
        raise GPR3DError("--init default: the package ships DepthNet as ONNX; start from its PyTorch twin, "
                         "references/depthnet/default_depthnet.pt")
    if args.max_seconds is not None and not args.max_seconds > 0:
        raise GPR3DError(f"--max-seconds must be positive, got {args.max_seconds}")
    from gpr3d.inversion.depthnet import DepthConfig

    net = DepthConfig(arch=args.arch, width=args.width)
    cfg = DepthTrainConfig(out=args.out, steps=args.steps or 2000, batch=args.batch or 16, lr=args.lr,
                           optimiser=args.optimiser, seed=args.seed, device=args.device,
                           checkpoint_every=args.checkpoint_every, net=asdict(net), init=args.init)
    if cfg.init:  # a wrong file fails here, in one line, before the records are prepared
        from gpr3d.inversion.depthnet import load_depthnet

        load_depthnet(cfg.init)
    packed = []
    if args.packed:
        from gpr3d.detection.data import PackedSource

        for item in args.packed:  # each checked in one line before any work
            part = PackedSource(item, holdout=args.packed_holdout).parts[0]
            packed.append((Path(item.rpartition(":")[0] if ":" in item else item).stem, part))
    out = Path(args.out)
    seed = 2000 if args.data_seed is None else args.data_seed  # apart from the detector's (1000) and tests' (777)
    folders = [cache_depth_records(SurveySource(seed), range(args.records), out / f"records_forward_{seed}")]
    for name, (ds, n) in packed:
        folders.append(cache_depth_records(lambda i, ds=ds: ds[i], range(n), out / f"records_{name}"))
    records = load_depth_records(folders[0])
    for f in folders[1:]:  # each packed set repeated to about a quarter of the forward records (at least once)
        recs = load_depth_records(f)
        records += recs * max(1, round(args.records / 4 / max(len(recs), 1)))
    res = train_depthnet(cfg, records, progress=not args.no_progress, max_seconds=args.max_seconds)
    val = validate_depthnet(res["model"], res["net"], SurveySource(seed + 1), 40)
    weights = out / "depthnet.pt"
    cmd = "gpr3d " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("gpr3d") else "gpr3d train depthnet"
    save_depthnet(res["model"], res["net"], weights,
                  provenance={"command": cmd, "config": asdict(cfg), "train_wall_s": res["wall_s"],
                              "steps_done": res["steps"], "parameters": res["parameters"],
                              "data": [f"survey_sample(seed={seed}, i < {args.records})"] + list(args.packed or []),
                              "validation": val})
    print(f"trained DepthNet ({res['parameters']} parameters) for {res['steps']} steps in {res['wall_s']:.0f} s; "
          f"validation eps_r relative RMSE {val['eps_rel_rmse']:.3f}, depth MAE {val['depth_mae_m']:.3f} m; "
          f"wrote {weights}")
    return 0


def _check_train_args(args) -> None:
    """train's numbers, before any data or model is made (a 0 once meant 'the default': hours of training)."""
    _in_range(args.steps, "--steps", 1, 10**7, "a number of optimiser steps")
    _in_range(args.batch, "--batch", 1, 4096, "a number of windows per step")
    _in_range(args.lr, "--lr", 1e-9, 10.0, "a positive learning rate")
    _in_range(args.warmup, "--warmup", 0, 10**7, "a number of steps")
    _in_range(args.workers, "--workers", 0, 256, "a number of data-loading processes")
    _in_range(args.checkpoint_every, "--checkpoint-every", 1, 10**7, "a number of steps")
    _in_range(args.max_seconds, "--max-seconds", 1e-3, 1e9, "a positive time in seconds")
    # (--labels-fraction and --packed-fraction: TrainConfig says 0..1 in its own words)
    _in_range(args.packed_holdout, "--packed-holdout", 0, 10**7, "a number of records")
    _in_range(args.width, "--width", 1, 1024, "a number of channels")
    _writable(args.out, "--out")


NAME = "train"
HELP = "train the hyperbola detector or DepthNet on survey-scale B-scans (resumable)"
EPILOG = ("examples:\n  gpr3d train detector --out det_run --steps 3000 --batch 8          (CPU)\n"
             "  gpr3d train depthnet --out dn_run --packed datasets/gprmax400.h5 datasets/gprmax_survey_train.h5:0\n"
             "  gpr3d train detector --out det_run --steps 6000 --batch 16 --device cuda --workers 12\n"
             "  gpr3d train detector --init default --labels my_bscans/coco.json --steps 300 --out ft   "
             "(fine-tune on your labels)\n"
             "re-run the same command to resume after a kill; weights go to OUT/weights.pt")


def add_arguments(sp):
    sp.add_argument("what", choices=("detector", "depthnet"), help="what to train")
    sp.add_argument("--out", required=True, help="run folder (checkpoint.pt, losses.csv, weights.pt)")
    sp.add_argument("--model", default="frcnn_lean", help="frcnn_lean (default), frcnn_r18/r50/r101, "
                    "frcnn_mobilenet, retinanet_r18, fcos_r18, ssdlite")
    sp.add_argument("--steps", type=int, default=None, help="optimiser steps (default 3000; depthnet 2000)")
    sp.add_argument("--batch", type=int, default=None, help="windows per step (default 8; depthnet 16)")
    sp.add_argument("--arch", default="resnet10n",
                    help="depthnet encoder: resnet10n (default, trains on CPU), resnet18/34/50/101 (the reference)")
    sp.add_argument("--width", type=int, default=24, help="depthnet: first-stage channels of resnet10n (24)")
    sp.add_argument("--records", type=int, default=1500,
                    help="depthnet: forward-model records to train on (prepared once into OUT; default 1500)")
    sp.add_argument("--lr", type=float, default=None, help="learning rate (default: the optimiser's)")
    sp.add_argument("--optimiser", default="adamw",
                    help="adamw (default), sgd (detector), reference (the paper's SGD: lr 4e-5, momentum 0.9)")
    sp.add_argument("--warmup", type=int, default=200, help="steps of linear learning-rate warm-up (default 200)")
    sp.add_argument("--seed", type=int, default=0, help="initialisation seed")
    sp.add_argument("--data-seed", type=int, default=None,
                    help="synthetic records survey_sample(SEED, i) (default 1000; depthnet 2000)")
    sp.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:N")
    sp.add_argument("--workers", type=int, default=0, help="data-loading processes (default 0)")
    sp.add_argument("--checkpoint-every", type=int, default=100, help="steps between checkpoints")
    sp.add_argument("--max-seconds", type=float, default=None, help="stop after this long (resume later)")
    sp.add_argument("--init", default=None, help="start from these weights (fine-tuning); 'default': the shipped ones")
    sp.add_argument("--labels", default=None,
                    help="your own labelled B-scans mixed in: a YOLO dataset (data.yaml, or a folder with images/ "
                         "and labels/), COCO .json, Pascal VOC .xml or a folder of them (images may be radar files "
                         "or pictures; see docs/CONVENTIONS.md)")
    sp.add_argument("--labels-fraction", type=float, default=0.5, help="share of windows from --labels (0.5)")
    add_label_args(sp)
    sp.add_argument("--kinds", default=None, metavar="K,K",
                    help="target kinds the detector tells apart, e.g. rebar,steel_pipe,pvc_pipe,void,tank "
                         "(default: those of --init; a one-class --init is widened to them)")
    sp.add_argument("--freeze", type=int, default=0,
                    help="backbone stages kept fixed: 1 the stem, 2 with layer1 (faster CPU fine-tuning; default 0)")
    sp.add_argument("--packed", nargs="+", default=None,
                    help="mix records of packed datasets in, each FILE or FILE:N (its last N held out; default "
                         "--packed-holdout), e.g. datasets/gprmax400.h5 datasets/gprmax_survey_train.h5:0")
    sp.add_argument("--packed-fraction", type=float, default=0.2, help="share of windows from --packed (0.2)")
    sp.add_argument("--packed-holdout", type=int, default=60, help="last records of --packed kept out (60)")
    sp.add_argument("--wall-fraction", type=float, default=0.0,
                    help="detector: share of the synthetic records drawn as handheld concrete wall scans at 1.2-2 "
                         "GHz (the 'wall' profile of gpr3d.simulation.surveys; 0, the default: none)")
    sp.add_argument("--augment", action="store_true",
                    help="detector: stretch the training windows along the traces (0.7-1.4x), change their gain "
                         "(0.6-1.8x) and add noise (up to 0.15 of the amplitude)")
    sp.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args):
    from dataclasses import asdict

    _check_train_args(args)
    if args.what == "depthnet":
        return cmd_train_depthnet(args)

    from gpr3d.detection.train import TrainConfig, train_detector
    from gpr3d.detection.weights import save_weights
    from gpr3d.simulation.surveys import SurveySource

    if args.max_seconds is not None and not args.max_seconds > 0:
        raise GPR3DError(f"--max-seconds must be positive, got {args.max_seconds}")
    cfg = TrainConfig(out=args.out, model=args.model, steps=args.steps or 3000, batch=args.batch or 8, lr=args.lr,
                      optimiser=args.optimiser, warmup=args.warmup, seed=args.seed,
                      data_seed=1000 if args.data_seed is None else args.data_seed,
                      device=args.device,
                      workers=args.workers, checkpoint_every=args.checkpoint_every, init=args.init,
                      packed=args.packed, packed_fraction=args.packed_fraction, packed_holdout=args.packed_holdout,
                      labels=args.labels, labels_fraction=args.labels_fraction, pixel_map=args.pixel_map,
                      labels_names=_names_list(args.class_names), labels_kinds=args.class_kinds,
                      labels_frequency_hz=args.labels_frequency, kinds=_names_list(args.kinds), freeze=args.freeze,
                      augment=args.augment or None, wall_fraction=args.wall_fraction)
    if cfg.packed:  # a wrong packed file (or hold-out) fails in one line before any model is built
        from gpr3d.detection.data import PackedSource

        PackedSource(cfg.packed, holdout=cfg.packed_holdout)
    if cfg.labels:  # a wrong label file fails in one line before any model is built
        _read_labels(args, cfg.labels)
    wall = SurveySource(cfg.data_seed, profile="wall", box_pad=cfg.wall_box_pad,
                        pad_wavelet=cfg.wall_pad_wavelet) if cfg.wall_fraction else None
    res = train_detector(cfg, SurveySource(cfg.data_seed), wall_source=wall, progress=not args.no_progress,
                         max_seconds=args.max_seconds)
    weights = Path(args.out) / "weights.pt"
    cmd = "gpr3d " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("gpr3d") else "gpr3d train detector"
    save_weights(res["model"], cfg.model, cfg.window, weights, kinds=res.get("kinds"),
                 provenance={"name": cfg.model, "command": cmd, "config": asdict(cfg), "train_wall_s": res["wall_s"],
                             "device": cfg.device,
                             "data": f"survey_sample(seed={cfg.data_seed}, i)" + (
                                 f" ({cfg.wall_fraction:.0%} of them profile='wall')" if cfg.wall_fraction else ""),
                             "steps_done": res["steps"], **_labels_provenance(cfg.labels)})
    print(f"trained {cfg.model} for {res['steps']} steps in {res['wall_s']:.0f} s; wrote {weights}")
    return 0
