"""Train several detectors one after another on the survey-scale synthetic data (GPU or CPU).

Used for the comparison table and the default weights, e.g. on a GPU machine:

    PYTHONPATH=src python references/detection/train_many.py --device cuda --out runs \
        --plan frcnn_lean:4000 frcnn_r50:1500 ssdlite:3000 --batch 16 --workers 12

Each model lands in ``runs/NAME/`` (checkpoint, losses.csv) and ``runs/NAME.pt`` (weights).
"""

import argparse
import json
import sys
import time
from dataclasses import asdict

from gpr3d.detection.train import TrainConfig, train_detector
from gpr3d.detection.weights import save_weights
from gpr3d.simulation.surveys import SurveySource


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", required=True)
    p.add_argument("--plan", nargs="+", required=True, help="NAME:STEPS ...")
    p.add_argument("--device", default="cpu")
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--workers", type=int, default=0)
    p.add_argument("--data-seed", type=int, default=1000)
    p.add_argument("--lr", type=float, default=None)
    p.add_argument("--max-seconds", type=float, default=None, help="per model")
    p.add_argument("--init", default=None, help="weights to start from")
    p.add_argument("--packed", default=None, help="packed dataset mixed in")
    p.add_argument("--packed-fraction", type=float, default=0.2)
    p.add_argument("--warmup", type=int, default=200)
    p.add_argument("--copy-to", default=None, help="also copy each NAME.pt and losses there")
    args = p.parse_args()
    summary = {}
    for item in args.plan:
        name, steps = item.split(":")
        cfg = TrainConfig(out=f"{args.out}/{name}", model=name, steps=int(steps), batch=args.batch,
                          device=args.device, workers=args.workers, data_seed=args.data_seed, lr=args.lr,
                          checkpoint_every=250, init=args.init, packed=args.packed,
                          packed_fraction=args.packed_fraction, warmup=args.warmup)
        t = time.perf_counter()
        res = train_detector(cfg, SurveySource(args.data_seed), progress=False, log=print, max_seconds=args.max_seconds)
        wall = time.perf_counter() - t
        cmd = "python references/detection/train_many.py " + " ".join(sys.argv[1:])
        save_weights(res["model"], name, cfg.window, f"{args.out}/{name}.pt",
                     provenance={"name": name, "command": cmd, "config": asdict(cfg), "train_wall_s": wall,
                                 "device": args.device, "data": f"survey_sample(seed={args.data_seed}, i)",
                                 "steps_done": res["steps"]})
        summary[name] = {"steps": res["steps"], "wall_s": wall, "parameters": res["parameters"]}  # steps done
        if args.copy_to:
            import shutil
            shutil.copy(f"{args.out}/{name}.pt", f"{args.copy_to}/{name}.pt")
            shutil.copy(f"{args.out}/{name}/losses.csv", f"{args.copy_to}/{name}_losses.csv")
        print(json.dumps({name: summary[name]}), flush=True)
        for d in [args.out] + ([args.copy_to] if args.copy_to else []):
            with open(f"{d}/summary.json", "w") as f:
                json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()
