"""Fine-tune the shipped detector on P-GPR's real 1.6 GHz B-scans (train split), on the CPU.

    python references/detection/finetune_pgpr.py --out runs/ft_pgpr [--pgpr ../shared/data/real/pgpr_1600MHz]

The shipped one-class detector is widened to gpr3d's five target kinds (each kind starts
as a copy of 'hyperbola', so the first step finds what the shipped model finds) and
trained on a mix: ``--real`` of the windows from P-GPR train (steel -> rebar, pipe ->
pvc_pipe; 256 rows = 8 ns), the rest survey-scale synthetic records (and, with
``--packed``, ``--packed-fraction`` of them packed gprMax B-scans). The shipped default
is the first form (``--steps 2000``, 75 % real, no packed records). Measured on the
held-out gprMax survey set, both lose mAP@0.75 against the one-class model they start
from (0.615 -> 0.442, and 0.362 with 60 % real and the stage-3 packed mix): P-GPR's
tight boxes and gpr3d's label rule (``docs/labels.md``) are two box conventions that
one box regression serves only in part. The stem
and layer1 stay fixed (``--freeze 2``): a step of 4 windows takes about 1.5 s on 2 cores.
Resumes after a kill (run the same line again); ``--max-seconds`` bounds one sitting.

``--real 0`` reads no P-GPR label at all: with ``--wall F`` (a share F of the synthetic
records drawn as handheld wall scans, ``survey_sample(..., profile="wall")``) this trains
the zero-shot model of issue 29 item 5. ``--only 'AIR_*'`` trains on one radar's pictures
(the device-held-out split; ``benchmarks/eval_pgpr.py --split train,val --only 'IECAS_*'``
tests it on the other's).

P-GPR: Yue, Qin, Zhu, Ye, Wang, "P-GPR: a Ground Penetrating Radar Dataset for Pipeline
Detection", CIKM '26; CC BY 4.0. Weights trained on it carry that credit in their provenance.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path

from gpr3d.detection.train import TrainConfig, train_detector
from gpr3d.detection.weights import save_weights
from gpr3d.io.coco import CATEGORIES
from gpr3d.simulation.surveys import SurveySource

PGPR_CREDIT = ("P-GPR dataset (train split): Yue, Qin, Zhu, Ye, Wang, 'P-GPR: a Ground Penetrating Radar Dataset "
               "for Pipeline Detection', CIKM '26; repository aiiseverything/P-GPR-Dataset; licence CC BY 4.0")
PGPR = dict(labels_names=["steel", "pipe"], labels_kinds="pipe=pvc_pipe", pixel_map="s_per_px=3.125e-11",
            labels_frequency_hz=1.6e9)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--pgpr", default=str(Path(__file__).resolve().parents[3] / "shared/data/real/pgpr_1600MHz"))
    p.add_argument("--split", default="train")
    p.add_argument("--init", default="default")
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--real", type=float, default=0.75, help="share of windows from P-GPR")
    p.add_argument("--freeze", type=int, default=2)
    p.add_argument("--max-seconds", type=float, default=None)
    p.add_argument("--only", default=None, help="train on these pictures only (a glob: AIR_* for one radar)")
    p.add_argument("--packed", nargs="*", default=[],
                   help="packed gprMax datasets mixed into the synthetic share (FILE:N holds out its last N), e.g. "
                        "the stage-3 mix datasets/gprmax400.h5:60 and datasets/gprmax_survey_train.h5:40 four times")
    p.add_argument("--packed-fraction", type=float, default=0.6, help="share of the non-P-GPR windows from --packed")
    p.add_argument("--wall", type=float, default=0.0,
                   help="share of the synthetic records drawn as handheld wall scans (survey_sample(..., profile='wall'))")
    p.add_argument("--wall-ringing", type=float, default=0.0,
                   help="share of the wall scans whose echoes ring (gpr3d.simulation.surveys.echo_ringing)")
    p.add_argument("--wall-box-pad", type=float, default=None, metavar="PERIODS",
                   help="the wall scans' boxes reach this many periods before the apex and after the latest arrival "
                        "(default the label rule's 0.7; 0.4: the Ricker's side lobes, the first lobe a picture shows)")
    p.add_argument("--wall-pad-wavelet", action="store_true",
                   help="the wall scans' box pad in periods of each record's drawn wavelet (its true centre "
                        "frequency, 0.8-1.2x the label's), not of the label's frequency")
    p.add_argument("--augment", action="store_true",
                   help="stretch the windows along the traces, change their gain and noise (gpr3d.detection.augment)")
    p.add_argument("--seed", type=int, default=0,
                   help="the network's seed (TrainConfig.seed); the window draws' seed is 1000 + it (data_seed): "
                        "another seed trains a twin of the same recipe, e.g. a member of an ensemble")
    p.add_argument("--stretch", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="with --augment: the trace-axis stretch's range (default 0.7 1.4; the two radars' hyperbolas "
                        "differ about 2.5x in width)")
    args = p.parse_args(argv)
    if not 0.0 <= args.wall <= 1.0 or not 0.0 <= args.real <= 1.0:
        p.error("--wall and --real are shares in 0..1")
    if args.wall_box_pad is not None and not args.wall:
        p.error("--wall-box-pad sets the wall scans' boxes: give --wall too")
    if args.wall_box_pad is not None and not 0.0 <= args.wall_box_pad <= 2.0:
        p.error(f"--wall-box-pad must lie in 0..2 periods, got {args.wall_box_pad:g}")
    if args.wall_pad_wavelet and not args.wall:
        p.error("--wall-pad-wavelet sets the wall scans' boxes: give --wall too")
    if args.stretch and not args.augment:
        p.error("--stretch is the range of --augment's stretch: give --augment too")
    if args.stretch and not 0.25 <= args.stretch[0] <= args.stretch[1] <= 4.0:
        p.error(f"--stretch must satisfy 0.25 <= LOW <= HIGH <= 4, got {args.stretch[0]:g} {args.stretch[1]:g}")
    if args.seed < 0:
        p.error(f"--seed must be 0 or more, got {args.seed}")
    zero_shot = args.real == 0  # no P-GPR label read: the zero-shot model of issue 29 item 5
    cfg = TrainConfig(out=args.out, init=args.init, kinds=list(CATEGORIES), steps=args.steps, batch=args.batch,
                      lr=args.lr, warmup=50, labels=None if zero_shot else str(Path(args.pgpr) / args.split), labels_fraction=args.real,
                      freeze=args.freeze, checkpoint_every=50, labels_pattern=args.only,
                      packed=args.packed or None, packed_fraction=args.packed_fraction,
                      augment=({"stretch": tuple(args.stretch)} if args.stretch else True) if args.augment else None,
                      wall_fraction=args.wall, wall_box_pad=args.wall_box_pad,
                      wall_pad_wavelet=args.wall_pad_wavelet, seed=args.seed, data_seed=1000 + args.seed,
                      **PGPR)
    wall = SurveySource(cfg.data_seed, profile="wall", ringing=args.wall_ringing,
                        box_pad=args.wall_box_pad, pad_wavelet=args.wall_pad_wavelet) if args.wall else None
    res = train_detector(cfg, SurveySource(cfg.data_seed), wall_source=wall, progress=False,
                         max_seconds=args.max_seconds)
    if res["steps"] < cfg.steps:
        print(f"step {res['steps']} of {cfg.steps}; run the same line again to continue")
        return 0
    weights = Path(args.out) / "weights.pt"
    width = None  # how wide the real training pictures' features are: what --trace-scales auto stretches records to
    if not zero_shot:
        import numpy as np

        from gpr3d.detection.windows import WindowConfig, prepare, trace_width
        from gpr3d.io.yolo import read_yolo

        window = WindowConfig(**cfg.window)  # (the config holds the window's settings as a dict)
        width = float(np.median([trace_width(prepare(s, window)) for s, _ in
                                 read_yolo(Path(args.pgpr) / args.split, pattern=args.only, names=PGPR["labels_names"],
                                           kinds=PGPR["labels_kinds"], pixel_map=PGPR["pixel_map"],
                                           frequency_hz=PGPR["labels_frequency_hz"])]))
    save_weights(res["model"], cfg.model, cfg.window, weights, kinds=res["kinds"],
                 provenance={"name": cfg.model, "command": "python " + " ".join(sys.argv), "config": asdict(cfg),
                             "train_wall_s": res["wall_s"], "device": "cpu",
                             **({} if zero_shot else {"credit": PGPR_CREDIT}),
                             "data": f"{args.real:.0%} P-GPR {args.split} windows"
                                     + (f" ({args.only})" if args.only else "") + "; of the rest, "
                                     + (f"{args.packed_fraction:.0%} packed gprMax records ({' '.join(args.packed)}), "
                                        if args.packed else "") + f"the others survey_sample(seed={cfg.data_seed}, i)"
                                     + (f" ({args.wall:.0%} of them wall scans, profile 'wall'"
                                        + (f", {args.wall_ringing:.0%} of those ringing" if args.wall_ringing else "")
                                        + (f", boxes padded {args.wall_box_pad:g} periods" if args.wall_box_pad
                                           is not None else "")
                                        + (", boxes padded in the drawn wavelet's periods" if args.wall_pad_wavelet
                                           else "")
                                        + ")" if args.wall else "")
                                     + (f"; augmented {cfg.augment}" if cfg.augment else ""),
                             "steps_done": res["steps"], **({"trace_width": width} if width else {})})
    print(json.dumps({"weights": str(weights), "steps": res["steps"], "wall_s": res["wall_s"]}))
    return 0


if __name__ == "__main__":
    from gpr3d.core.errors import GPR3DError

    try:
        sys.exit(main())
    except GPR3DError as e:  # a wrong setting or file: one line, as the gpr3d commands answer
        sys.exit(f"finetune_pgpr.py: {e}")
