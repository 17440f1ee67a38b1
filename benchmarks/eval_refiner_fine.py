"""The box refiner with and without a fine stage: a second refiner, trained on boxes drawn closer to the labels, that
moves each box once more after the first refiner's passes.

    python benchmarks/eval_refiner_fine.py [--fine default FILE ...] [--refiner default|FILE]
        [--pgpr P-GPR_FOLDER] [--set datasets/gprmax_survey.h5] [--out DIR] [--name refiner_fine.md]

The shipped detector's network sees each record once; every setting refines the same merged boxes again (the shipped
refiner at its defaults: two passes, each crop also mirrored, duplicates lowered) and is scored as
``benchmarks/eval_pgpr.py`` scores P-GPR's validation pictures (class-averaged over rebar and pvc_pipe, and
class-agnostic) and as ``benchmarks/eval_detector.py`` scores simulated sets (mAP, apex recall and false targets per
true one at score 0.5): the held-out gprMax survey set (``--set``), the last 60 records of ``datasets/gprmax400.h5``
and 60 synthetic survey records (``survey_sample(777, i)``). No model trains on any of them. The rows:

* ``none``: no fine stage (the refiner as shipped before the fine stage);
* ``default``: the shipped fine stage (``gpr3d.detection.refine.DEFAULT_FINE_REFINER``);
* a file: that fine stage (``references/detection/train_refiner.py --jitter-scale S``).

Writes ``--name`` in ``--out``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402
from eval_pgpr import PGPR_DEFAULT, load, pgpr_records  # noqa: E402
from eval_refiner_passes import network_once  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--fine", nargs="+", default=["none", "default"], help="fine stages compared: none, default, files")
    p.add_argument("--refiner", default="default", help="the first refiner: default (the shipped one) or a file")
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (its val/ split is used)")
    p.add_argument("--set", default=str(ROOT / "datasets" / "gprmax_survey.h5"), help="the held-out gprMax set")
    p.add_argument("--no-simulated", action="store_true", help="P-GPR val alone")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "intel"))
    p.add_argument("--name", default="refiner_fine.md")
    args = p.parse_args(argv)
    fines = args.fine
    for f in fines:
        if f not in ("none", "default") and not Path(f).is_file():
            p.error(f"--fine {f}: neither none, default nor an existing file")
    if len(set(fines)) != len(fines):
        p.error(f"--fine {' '.join(fines)}: each fine stage once")
    if args.refiner != "default" and not Path(args.refiner).is_file():
        p.error(f"--refiner {args.refiner}: no such file")
    if not (Path(args.pgpr) / "val").is_dir():
        p.error(f"--pgpr {args.pgpr}: no val/ folder in it (P-GPR's validation split)")
    if not args.no_simulated and not Path(args.set).is_file():
        p.error(f"--set {args.set}: no such file")
    if Path(args.name).name != args.name or not args.name.endswith(".md"):
        p.error(f"--name {args.name}: a file name ending in .md (no folder: --out says where)")
    if not Path(args.out).is_dir():
        p.error(f"--out {args.out}: not a folder")
    from gpr3d.core.errors import GPR3DError
    from gpr3d.detection.evaluate import evaluate_detector
    from gpr3d.detection.refine import load_refiner

    base = None if args.refiner == "default" else args.refiner
    try:  # every file read before any work: one that is not a refiner, or a stage that does not fit it, is one line
        refiners = {f: load_refiner(base, fine=None if f == "none" else f) for f in fines}
    except GPR3DError as exc:
        p.error(str(exc))
    det = network_once(load("default")[0])
    sets = [("P-GPR val", lambda: pgpr_records(args.pgpr, "val"))]
    if not args.no_simulated:
        from gpr3d.io.packed import labelled_records
        from gpr3d.simulation.surveys import survey_sample

        sets += [(Path(args.set).name, lambda: labelled_records(args.set)),
                 ("gprmax400.h5, last 60", lambda: labelled_records(ROOT / "datasets" / "gprmax400.h5", n=60,
                                                                    last=True)),
                 ("survey_sample(777, i < 60)", lambda: (survey_sample(777, i) for i in range(60)))]
    pg = ["| fine stage | P-GPR val class-averaged mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@100 | recall@0.5 | "
          "class-agnostic mAP@0.5 | class-agnostic mAP@[.5:.95] | refine s |", "|---|---|---|---|---|---|---|---|---|"]
    sim = ["| fine stage | set | mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@100 | apex recall | false per true | "
           "refine s |", "|---|---|---|---|---|---|---|---|---|"]
    t0 = time.perf_counter()
    for name, records in sets:
        records = list(records())
        for f in fines:
            det.refiner = refiners[f]
            t1 = time.perf_counter()
            m = evaluate_detector(det, records)
            dt = time.perf_counter() - t1
            label = {"none": "none", "default": "shipped"}.get(f, Path(f).name)
            if name == "P-GPR val":
                k = m["by_kind"]
                pg.append(f"| {label} | {k['mAP@0.5']:.3f} | {k['mAP@0.75']:.3f} | {k['mAP']:.3f} | {k['AR@100']:.3f} | "
                          f"{k['recall@0.5']:.3f} | {m['mAP@0.5']:.3f} | {m['mAP']:.3f} | {dt:.1f} |")
                print(pg[-1], flush=True)
            else:
                sim.append(f"| {label} | {name} | {m['mAP@0.5']:.3f} | {m['mAP@0.75']:.3f} | {m['mAP']:.3f} | "
                           f"{m['AR@100']:.3f} | {m['apex_recall']:.3f} | {m['false_per_true']:.3f} | {dt:.1f} |")
                print(sim[-1], flush=True)
    head = (f"The shipped detector ({det.provenance.get('name', 'default')}) and first refiner "
            f"({next(iter(refiners.values())).provenance.get('name', 'refiner')}), each fine stage applied to the same "
            f"network boxes; host CPU {cpu_name()}; {time.perf_counter() - t0:.0f} s in all. 'refine s': the seconds "
            "for the set: refining, scoring and the rest, and in each set's first row the network's views too")
    parts = [head, "", *pg]
    if len(sim) > 2:
        parts += ["", "Simulated sets (score 0.5 for apex recall and false targets):", "", *sim]
    write_table(Path(args.out), args.name, "\n".join(parts), "eval_refiner_fine.py", argv)


if __name__ == "__main__":
    main()
