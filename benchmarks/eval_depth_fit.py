"""Classical hyperbola fit: permittivity and depth against gprMax truth (issue 9's baseline, work in progress).

    python benchmarks/eval_depth_fit.py [--survey build/gprmax_survey_4242] [--out benchmarks/results]

Two sets:
* gprMax's own example ``cylinder_Bscan_2D.in`` (shipped in the gprMax wheel: eps_r 6, PEC
  cylinder of 10 mm radius, top 80 mm deep, 60 traces), run here (about 20 s), fitted inside
  the detector's box (the shipped detector) and inside a box below the direct wave;
* the held-out gprMax survey set (``--survey``: packed file or ``gpr3d simulate`` folder),
  fitted inside every labelled box (truth boxes: the fit alone is judged).

Prints Markdown tables (point / cylinder / auto models) and writes ``depth_fit.md``.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import math
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402
MODELS = ("point", "cylinder", "auto", "radius given", "joint point", "joint cylinder")


def gprmax_example(work: Path):
    """The merged B-scan of gprMax's cylinder_Bscan_2D example (run once, kept in ``work``)."""
    import gprMax
    from gprMax.toolboxes.Utilities.outputfiles_merge import merge_files

    import gpr3d

    merged = work / "cylinder_Bscan_2D_merged.h5"
    if not merged.exists():
        work.mkdir(parents=True, exist_ok=True)
        src = Path(gprMax.__file__).parent / "_examples" / "gpr" / "basic" / "cylinder_Bscan_2D.in"
        shutil.copy(src, work / src.name)
        with contextlib.redirect_stdout(io.StringIO()):
            gprMax.run(inputfile=str(work / src.name), n=60, hide_progress_bars=True, log_level=40)
        merge_files([work / f"cylinder_Bscan_2D{i}.h5" for i in range(1, 61)], merged)
        for i in range(1, 61):
            (work / f"cylinder_Bscan_2D{i}.h5").unlink(missing_ok=True)
    # the input file's Ricker is 1.5 GHz; gprMax outputs carry no antenna frequency
    return gpr3d.read(merged).replace(frequency_hz=1.5e9)


def main(argv=None):
    from gpr3d.inversion.hyperbola import combine_permittivity, fit_boxes, fit_record

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--survey", default=str(ROOT / "build" / "gprmax_survey_4242"))
    p.add_argument("--work", default=str(ROOT / "build" / "gprmax_example"))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--truth-apex", action="store_true", help="start the tracking at the labelled apexes")
    p.add_argument("--n", type=int, default=None, help="only the first N records of --survey")
    p.add_argument("--no-example", action="store_true", help="skip gprMax's example")
    p.add_argument("--models", nargs="+", choices=MODELS, default=list(MODELS), metavar="MODEL",
                   help=f"fits to run on --survey (default all: {', '.join(MODELS)})")
    args = p.parse_args(argv)
    lines = [f"Host CPU: {cpu_name()}", "", "### gprMax example cylinder_Bscan_2D (eps_r 6, top 0.080 m, radius 0.010 m)",
             "", "| box | model | eps_r | sigma | error % | depth m | error mm | radius m | time zero ns (true 0.943) |",
             "|---|---|---|---|---|---|---|---|---|"]
    s = gprmax_example(Path(args.work))
    boxes = {} if args.no_example else {"below the direct wave": [0, 1.9e-9, 59, 3e-9]}
    apex = {}
    try:
        if args.no_example:
            raise RuntimeError("--no-example")
        from gpr3d.detection.infer import load_detector

        found = load_detector().detect(s, score_threshold=0.3)["targets"]
        if found:
            boxes["detector's box"] = found[0]["box"]
            apex["detector's box"] = (found[0]["apex_trace"], found[0]["apex_time_s"])
    except Exception as exc:  # noqa: BLE001 - the detector is optional here
        print(f"detector not run: {exc}", file=sys.stderr)
    for name, box in boxes.items():
        for model in ("point", "cylinder", "auto", "radius given"):
            f = fit_boxes(s, [box], model="cylinder" if model == "radius given" else model,
                          apexes=[apex[name]] if name in apex else None,
                          radius_m=0.010 if model == "radius given" else None)[0]
            shown = {"auto": f"{f.model} (auto)", "radius given": "cylinder, radius 10 mm given"}.get(model, model)
            lines.append(f"| {name} | {shown} | "
                         f"{f.eps_r:.3f} | {f.sigma_eps_r:.3f} | {100 * (f.eps_r - 6) / 6:+.1f} | {f.depth_m:.4f} | "
                         f"{1000 * (f.depth_m - 0.08):+.1f} | {f.radius_m:.4f} | {f.t0_s * 1e9:.3f} |")
    survey = Path(args.survey)
    if survey.exists():
        from gpr3d.io.packed import labelled_records

        rows = []
        n_rec = 0
        for s, lab in labelled_records(survey, n=args.n):
            n_rec += 1
            vis = [x for x in lab["labels"] if x["visible"]]
            ap = [(x["apex_trace"], x["apex_time_s"]) for x in vis] if args.truth_apex else None
            for model in args.models:
                if model.startswith("joint"):
                    fits, info = fit_record(s, [x["box"] for x in vis], model=model.split()[1], apexes=ap)
                    rec_eps = info["eps_r"]
                elif model == "radius given":  # each target's true radius, as a user who knows it
                    fits = fit_boxes(s, [x["box"] for x in vis], model="cylinder", apexes=ap,
                                     radius_m=[x["radius_m"] for x in vis])
                    rec_eps = combine_permittivity(fits)[0]
                else:
                    fits = fit_boxes(s, [x["box"] for x in vis], model=model, apexes=ap)
                    rec_eps = combine_permittivity(fits)[0]
                for x, f in zip(vis, fits):
                    rows.append((model, x["kind"], x["depth_m"], lab["eps_r"], f, rec_eps))
        lines += ["", f"### gprMax survey set {survey.name}: {n_rec} records, truth boxes", "",
                  "| model | kind | targets | fitted | eps_r MAPE | record eps_r MAPE | record eps_r bias | "
                  "record eps_r RMS | depth MAE m | depth MAE m (top < 0.3 m) |", "|---|---|---|---|---|---|---|---|---|---|"]
        for model in args.models:
            groups = collections.defaultdict(list)
            for r in rows:
                if r[0] == model:
                    groups[r[1]].append(r)
                    groups["all"].append(r)
            for kind in sorted(groups, key=lambda k: (k != "all", k)):
                g = groups[kind]
                ok = [r for r in g if r[4].ok]
                mape = np.mean([abs(r[4].eps_r - r[3]) / r[3] for r in ok]) if ok else math.nan
                rel = np.array([(r[5] - r[3]) / r[3] for r in ok if math.isfinite(r[5])])
                rmape = np.mean(np.abs(rel)) if rel.size else math.nan
                bias = np.mean(rel) if rel.size else math.nan
                rms = np.sqrt(np.mean(rel**2)) if rel.size else math.nan
                mae = np.mean([abs(r[4].depth_m - r[2]) for r in ok]) if ok else math.nan
                sh = [abs(r[4].depth_m - r[2]) for r in ok if r[2] < 0.3]
                lines.append(f"| {model} | {kind} | {len(g)} | {len(ok)} | {mape:.3f} | {rmape:.3f} | {bias:+.3f} | "
                             f"{rms:.3f} | {mae:.4f} | "
                             f"{np.mean(sh) if sh else math.nan:.4f} |")
    out = Path(args.out)
    write_table(out, "depth_fit.md", "\n".join(lines), "eval_depth_fit.py", argv)


if __name__ == "__main__":
    main()
