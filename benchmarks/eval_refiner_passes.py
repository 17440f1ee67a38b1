"""How the box refiner is applied: once or in several passes, with each crop also seen mirrored or not.

    python benchmarks/eval_refiner_passes.py [--passes 1,2,3] [--sets pgpr gprmax_survey] [--out benchmarks/results]

The shipped detector and the shipped refiner (:mod:`gpr3d.detection.refine`), on P-GPR's
real validation B-scans (``eval_pgpr.py``'s reading; class-averaged over rebar and
pvc_pipe, and class-agnostic) and on the held-out gprMax survey set (``eval_detector.py``'s;
class-agnostic, with apex recall and false targets per true one at score 0.5). The
network runs once per record; each setting refines its merged boxes again. Neither set
trains the refiner or the detector. Writes ``pgpr_refiner_passes.md`` in ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402

KEYS = ("mAP@0.5", "mAP@0.75", "mAP", "AR@100", "recall@0.5")


def network_once(det):
    """``det`` with its network's views of each record computed once (keyed by the record object), whatever refines
    them afterwards."""
    seen, plain = {}, det._views

    def views(survey):
        key = id(survey)
        if key not in seen:
            seen[key] = (survey, plain(survey))
        return seen[key][1]

    det._views = views
    return det


def _settings(text: str):
    try:
        passes = [int(v) for v in text.split(",")]
    except ValueError:
        passes = []
    if not passes or not all(1 <= p <= 5 for p in passes):
        raise SystemExit(f"eval_refiner_passes: --passes must be whole numbers in 1..5 separated by commas, got {text!r}")
    return [(None, None)] + [(m, p) for m in (False, True) for p in passes]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--passes", default="1,2,3", help="the passes to compare, each without and with the mirror")
    p.add_argument("--sets", nargs="+", default=["pgpr", "gprmax_survey"], choices=("pgpr", "gprmax_survey"))
    p.add_argument("--pgpr", default=None, help="P-GPR folder (train/ and val/; default ../shared/data/real/...)")
    p.add_argument("--gprmax-survey", default=str(ROOT / "datasets" / "gprmax_survey.h5"))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    settings = _settings(args.passes)
    if "pgpr" in args.sets:
        from eval_pgpr import PGPR_DEFAULT, pgpr_records

        folder = Path(args.pgpr) if args.pgpr else PGPR_DEFAULT
        if not (folder / "val").is_dir():
            raise SystemExit(f"eval_refiner_passes: no P-GPR val/ folder in {folder}")
    if "gprmax_survey" in args.sets and not Path(args.gprmax_survey).is_file():
        raise SystemExit(f"eval_refiner_passes: no held-out gprMax survey set at {args.gprmax_survey}")

    from gpr3d.detection.evaluate import evaluate_detector
    from gpr3d.detection.infer import load_detector
    from gpr3d.detection.refine import load_refiner

    lines = [f"The shipped detector with the shipped refiner applied in each way; host CPU {cpu_name()}, torch "
             "threads as set by the environment", ""]
    for name in args.sets:
        if name == "pgpr":
            recs = pgpr_records(folder, "val")
            head = ("P-GPR val (56 real B-scans): class-averaged (rebar, pvc_pipe) mAP@0.5 / mAP@0.75 / mAP@[.5:.95] "
                    "/ AR@100 / recall@0.5, then the same class-agnostic")
        else:
            from gpr3d.io.packed import labelled_records

            recs = list(labelled_records(args.gprmax_survey))
            head = (f"held-out gprMax survey set ({len(recs)} records): class-agnostic mAP@0.5 / mAP@0.75 / "
                    "mAP@[.5:.95] / AR@100 / recall@0.5, apex recall and false per true at score 0.5")
        det = network_once(load_detector(engine="torch", refiner="none"))
        lines += [f"### {head}", "", "| refiner | mirror | passes | metrics | apex recall | false per true |",
                  "|---|---|---|---|---|---|"]
        for mirror, passes in settings:
            det.refiner = None if passes is None else load_refiner(mirror=mirror, passes=passes)
            m = evaluate_detector(det, recs)
            avg = " / ".join(f"{m['by_kind'][k]:.3f}" for k in KEYS) + " ; " if "by_kind" in m and name == "pgpr" else ""
            agn = " / ".join(f"{m[k]:.3f}" for k in KEYS)
            what = ("none (the network's boxes)", "-", "-") if passes is None else ("shipped", "yes" if mirror else "no",
                                                                                   str(passes))
            apex = "- | -" if name == "pgpr" else f"{m['apex_recall']:.3f} | {m['false_per_true']:.3f}"
            lines.append(f"| {what[0]} | {what[1]} | {what[2]} | {avg}{agn} | {apex} |")
            print(lines[-1], flush=True)
        lines.append("")
    lines.append("P-GPR's labels carry no apex of their own (its apex columns are left empty). Every setting refines "
                 "the same network boxes (PyTorch engine).")
    write_table(args.out, "pgpr_refiner_passes.md", "\n".join(lines), "eval_refiner_passes.py", argv)


if __name__ == "__main__":
    main()
