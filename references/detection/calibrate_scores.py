"""Fit a detector's score calibration (Platt scaling) on records it never trained on, and write it into its weights.

    python references/detection/calibrate_scores.py WEIGHTS.pt --out OUT.pt [--packed FILE.h5:N ...]
        [--synthetic SEED:N ...] [--refiner default|none|FILE] [--threads 2]

Every record is detected at a score floor of 0.05 with the weights' own scores (any calibration they carry is set
aside), each box is marked true when it matches a labelled target one-to-one at IoU >= 0.5
(:func:`gpr3d.detection.calibration.box_truth`), and the Platt map is fitted to those marks
(:func:`~gpr3d.detection.calibration.fit_platt`). ``OUT.pt`` is the same weights with
``provenance["score_calibration"]`` set; a table of raw thresholds, the share of true boxes above each and the
calibrated score they become is printed. The records:

* ``--packed FILE.h5:N``: the last N records of a packed gprMax file (what ``FILE:N`` held out of training);
* ``--synthetic SEED:N``: survey-scale synthetic records ``survey_sample(SEED, i)``, i < N. Seed 1000 (the
  detectors' training source) and 777 (the shipped weights' check set) are refused.

Nothing of the held-out gprMax survey set (``datasets/gprmax_survey.h5``) nor of P-GPR is read.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import numpy as np

FLOOR = 0.05
REFUSED_SEEDS = {1000: "the detectors' training source", 777: "the shipped weights' check set"}


def _pair(text: str, what: str, p) -> tuple[str, int]:
    head, sep, tail = text.rpartition(":")
    if not sep or not tail.isdigit() or int(tail) < 1:
        p.error(f"{what} {text}: expected NAME:N with N a whole number >= 1")
    return head, int(tail)


def records(packed, synthetic):
    """``(Survey, labels)`` of every calibration record, in order."""
    from gpr3d.io.packed import labelled_records
    from gpr3d.simulation.surveys import survey_sample

    for path, n in packed:
        yield from labelled_records(path, n=n, last=True)
    for seed, n in synthetic:
        for i in range(n):
            yield survey_sample(seed, i)


def collect(det, recs) -> tuple[np.ndarray, np.ndarray]:
    """Raw scores and true/false marks of every box ``det`` finds at the floor in ``recs``."""
    from gpr3d.detection.calibration import box_truth

    scores, truth = [], []
    for survey, labels in recs:
        vis = [x for x in labels["labels"] if x.get("visible", True)]
        tg = det.detect(survey, score_threshold=FLOOR)["targets"]
        px = np.array([1.0, 1.0 / survey.dt_s, 1.0, 1.0 / survey.dt_s])
        s = [t["score"] for t in tg]
        truth.extend(box_truth([np.asarray(t["box"]) * px for t in tg], s, [np.asarray(x["box"]) * px for x in vis]))
        scores.extend(s)
    return np.asarray(scores, float), np.asarray(truth, bool)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("weights", help="detector weights (.pt)")
    p.add_argument("--out", required=True, help="the calibrated weights (.pt; may be WEIGHTS itself)")
    p.add_argument("--packed", nargs="*", default=[], help="FILE.h5:N, its last N records")
    p.add_argument("--synthetic", nargs="*", default=[], help="SEED:N, survey_sample(SEED, i) for i < N")
    p.add_argument("--refiner", default="default", help="default (the shipped one), none, or a refiner file")
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args(argv)
    if not Path(args.weights).is_file():
        p.error(f"{args.weights}: no such file")
    if not str(args.weights).endswith(".pt"):
        p.error(f"{args.weights}: calibrate a .pt weights file (then export it: its graph carries the map)")
    if not str(args.out).endswith(".pt") or not Path(args.out).resolve().parent.is_dir():
        p.error(f"--out {args.out}: a .pt file in an existing folder")
    if not 1 <= args.threads <= 256:
        p.error(f"--threads must lie in 1..256, got {args.threads}")
    if args.refiner not in ("default", "none") and not Path(args.refiner).is_file():
        p.error(f"--refiner {args.refiner}: no such file (or default, none)")
    from gpr3d.core.errors import GPR3DError
    from gpr3d.io.packed import PackedDataset

    packed = [_pair(x, "--packed", p) for x in args.packed]
    for path, n in packed:  # each opened before any work: not a packed dataset, or too few records, is one line
        if not Path(path).is_file():
            p.error(f"--packed {path}: no such file")
        try:
            size = len(PackedDataset(path))
        except GPR3DError as exc:
            p.error(f"--packed {path}: {exc}")
        if n > size:
            p.error(f"--packed {path}:{n}: the file holds {size} records")
    synthetic = []
    for x in args.synthetic:
        seed, n = _pair(x, "--synthetic", p)
        if not seed.isdigit():
            p.error(f"--synthetic {x}: the seed must be a whole number")
        if int(seed) in REFUSED_SEEDS:
            p.error(f"--synthetic {x}: seed {seed} is {REFUSED_SEEDS[int(seed)]}; calibrate on records never "
                    "trained or checked on")
        synthetic.append((int(seed), n))
    if not packed and not synthetic:
        p.error("nothing to calibrate on: give --packed FILE.h5:N and/or --synthetic SEED:N")
    import torch

    from gpr3d.core.atomic import atomic_path
    from gpr3d.detection.calibration import calibrate, fit_platt
    from gpr3d.detection.infer import load_detector
    from gpr3d.detection.weights import FORMAT
    from gpr3d.io.weights import read_weights_file

    torch.set_num_threads(args.threads)
    try:
        det = load_detector(args.weights, engine="torch", refiner=args.refiner)
        obj = read_weights_file(args.weights, FORMAT, "detector")
    except GPR3DError as exc:
        p.error(str(exc))
    det.calibration = None  # the network's own scores are what the map is fitted to
    t0 = time.perf_counter()
    try:  # (a record that cannot be read, or marks that cannot be fitted: one line)
        scores, truth = collect(det, records(packed, synthetic))
        a, b = fit_platt(scores, truth)
    except GPR3DError as exc:
        p.error(str(exc))
    fit_on = ", ".join([f"the last {n} records of {Path(f).name}" for f, n in packed]
                       + [f"survey_sample({s}, i < {n})" for s, n in synthetic])
    cal = {"method": "platt", "a": a, "b": b, "fit_on": fit_on, "n_boxes": int(len(scores)),
           "n_true": int(truth.sum()), "score_floor": FLOOR, "truth": "one-to-one box match at IoU >= 0.5",
           "refiner": args.refiner if args.refiner in ("default", "none") else Path(args.refiner).name,
           "command": "python references/detection/calibrate_scores.py " + shlex.join(sys.argv[1:] if argv is None
                                                                                      else argv)}
    obj["provenance"] = {**obj.get("provenance", {}), "score_calibration": cal}
    with atomic_path(args.out, suffix=".pt.part") as tmp:
        torch.save(obj, tmp)
    print(f"{len(scores)} boxes ({int(truth.sum())} true) in {time.perf_counter() - t0:.0f} s; "
          f"Platt map a = {a:.4f}, b = {b:.4f}")
    print("| raw score >= | boxes | true share | calibrated score |\n|---|---|---|---|")
    for th in (0.05, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99):
        sel = scores >= th
        share = f"{truth[sel].mean():.3f}" if sel.any() else "-"
        print(f"| {th} | {int(sel.sum())} | {share} | {float(calibrate([th], cal)[0]):.3f} |")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
