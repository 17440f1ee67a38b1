"""Permittivity and depth: DepthNet, the hyperbola fit and the hybrid (issue 9), on held-out sets.

    python benchmarks/eval_depth.py [--weights FILE] [--n N] [--sets gprmax_survey,gprmax400,survey,example]

Sets (nothing here was trained or tuned on):
* ``gprmax_survey``: the held-out gprMax survey-scale set ``datasets/gprmax_survey.h5`` (seed 4242);
* ``gprmax400``: the last 60 records of ``datasets/gprmax400.h5`` (held out of every training);
* ``survey``: forward-model survey records of seed 777 (the detector's evaluation seed);
* ``example``: gprMax's own ``cylinder_Bscan_2D.in`` (eps_r 6, PEC cylinder of 10 mm radius, top 80 mm
  deep), run here once (about 20 s), with the shipped detector's box;
* ``real``: every recording in ``../shared/data/real`` (no truth: the estimates beside the header's eps_r),
  with the shipped detector's boxes (skipped when the folder is absent).

Labelled boxes and apexes are given (the estimates alone are judged). Prints Markdown tables and
writes ``benchmarks/results/depth.md``; ``gpr3d eval depth --data ...`` runs the same on any
labelled set.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402

SETS = ("gprmax_survey", "gprmax400", "survey", "example", "real")
REAL = ROOT.parent / "shared" / "data" / "real"


def records(name: str, n: int | None):
    from gpr3d.io.packed import labelled_records

    if name == "gprmax_survey":
        return labelled_records(ROOT / "datasets" / "gprmax_survey.h5", n=n)
    if name == "gprmax400":
        return labelled_records(ROOT / "datasets" / "gprmax400.h5", n=n or 60, last=True)
    from gpr3d.simulation.surveys import SurveySource

    src = SurveySource(777)
    return (src(i) for i in range(n or 30))


def example_rows(estimator, work: Path) -> list[str]:
    from eval_depth_fit import gprmax_example

    from gpr3d.detection.infer import load_detector
    from gpr3d.inversion.estimate import METHODS, estimate_depths

    s = gprmax_example(work)
    found = load_detector().detect(s, score_threshold=0.3)["targets"][:1]
    lines = ["| method | eps_r | sigma | error % | depth to top m | error mm |", "|---|---|---|---|---|---|"]
    if not found:
        return lines + ["| (the detector found no hyperbola) | | | | | |"]
    for m, radius in [(m, None) for m in METHODS] + [("fit", 0.010), ("hybrid", 0.010)]:
        r = estimate_depths(s, found, method=m, estimator=estimator, radius_m=radius)
        e, d = r["permittivity"]["eps_r"], r["targets"][0]["depth_m"]
        name = m if radius is None else f"{m}, radius 10 mm given"
        if m == "hybrid":
            name += " (fit agrees)" if r["permittivity"].get("fit_agrees") else " (fit left out: disagrees)"
        lines.append(f"| {name} | {e:.3f} | {r['permittivity']['sigma_eps_r']:.3f} | {100 * (e - 6) / 6:+.1f} | "
                     f"{d:.4f} | {1000 * (d - 0.08):+.1f} |")
    return lines


def real_rows(estimator) -> list[str]:
    import gpr3d
    from gpr3d.detection.infer import load_detector
    from gpr3d.inversion.estimate import estimate_depths

    lines = ["| file | traces | f MHz | window ns | header eps_r | detections | DepthNet | fit (hyperbolas) | hybrid |"
             " median depth m |", "|---|---|---|---|---|---|---|---|---|---|"]
    det = load_detector()
    exts = {".dzt", ".dt1", ".rd3"}
    for path in sorted(p for p in REAL.rglob("*") if p.suffix.lower() in exts):
        try:
            s = gpr3d.read(path)
        except Exception as exc:  # noqa: BLE001 - report and go on
            lines.append(f"| {path.relative_to(REAL)} | unreadable: {exc} | | | | | | | | |")
            continue
        found = det.detect(s, score_threshold=0.5)["targets"]
        if s.distances_m is None:
            lines.append(f"| {path.relative_to(REAL)} | {s.n_traces} | | | {s.eps_r} | {len(found)} | "
                         "no trace positions | | | |")
            continue
        r = estimate_depths(s, found, method="hybrid", estimator=estimator)
        p = r["permittivity"]
        fit = p.get("fit", {})
        d = [t["depth_m"] for t in r["targets"] if t["depth_m"] == t["depth_m"]]
        f_mhz = f"{s.frequency_hz / 1e6:.0f}" if s.frequency_hz else "?"
        lines.append(f"| {path.relative_to(REAL)} | {s.n_traces} | {f_mhz} | {s.time_window_s * 1e9:.0f} | "
                     f"{s.eps_r if s.eps_r else '-'} | {len(found)} | {p['net']['eps_r']:.2f} | "
                     f"{fit.get('eps_r', float('nan')):.2f} ({fit.get('n_hyperbolas', 0)}) | "
                     f"{p['eps_r']:.2f} +- {p['sigma_eps_r']:.2f} | "
                     f"{(sorted(d)[len(d) // 2] if d else float('nan')):.2f} |")
    return lines


def main(argv=None):
    from gpr3d.inversion.depthnet import DepthEstimator
    from gpr3d.inversion.evaluate import depth_rows, depth_table

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--weights", default=None, help="DepthNet weights (default: the shipped ones)")
    p.add_argument("--n", type=int, default=None, help="records per set (default: all of gprmax_survey, 60, 30)")
    p.add_argument("--sets", default=",".join(SETS))
    p.add_argument("--work", default=str(ROOT / "build" / "gprmax_example"))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    sets = [s for s in args.sets.split(",") if s]
    bad = [s for s in sets if s not in SETS]
    if bad:
        p.error(f"unknown set(s) {', '.join(bad)}; choose from {', '.join(SETS)}")
    est = DepthEstimator.load(args.weights)
    lines = [f"Host CPU: {cpu_name()}", f"DepthNet weights: {args.weights or 'shipped default'}", ""]
    for name in sets:
        t0 = time.perf_counter()
        if name == "real":
            if not REAL.exists():
                continue
            body = real_rows(est)
            title = "real recordings (../shared/data/real), the shipped detector's boxes, no truth"
        elif name == "example":
            body = example_rows(est, Path(args.work))
            title = "gprMax example cylinder_Bscan_2D (eps_r 6, top 0.080 m), the detector's box"
        else:
            rows = depth_rows(records(name, args.n), estimator=est)
            body = depth_table(rows)
            title = f"{name}: {len({r['record'] for r in rows})} records, labelled boxes"
        lines += [f"### {title} ({time.perf_counter() - t0:.0f} s)", ""] + body + [""]
        print("\n".join(lines[-len(body) - 3:]), flush=True)
    write_table(Path(args.out), "depth.md", "\n".join(lines), "eval_depth.py", argv)


if __name__ == "__main__":
    main()
