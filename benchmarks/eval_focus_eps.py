"""eps_r by migration focus against DepthNet / fit / hybrid on the demo's random-motion survey (issue 9).

The demo's cart crosses the pipes obliquely; a hyperbola read along the trace sequence is stretched by
1/sin(crossing angle) and gives a low eps_r. Migration velocity analysis (``gpr3d.migration.velocity.focus_eps``)
migrates the detected boxes in 3D from the antenna poses over a grid of eps_r around the hybrid estimate and
keeps the most focused image.

    gpr3d demo --out gpr3d_demo && python benchmarks/eval_focus_eps.py gpr3d_demo
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.migration.velocity import focus_eps  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("demo_dir", help="a gpr3d demo output folder (with detections)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    d = Path(args.demo_dir)
    for name in ("summary.json", "random_walk_survey.h5", "detections.json"):
        if not (d / name).exists():
            ap.error(f"{d / name} is missing: run `gpr3d demo --out {d}` with the dl extra first")
    summary = json.loads((d / "summary.json").read_text())
    depth = summary["stages"]["detection"]["depth"]["random_walk"]
    found = json.loads((d / "detections.json").read_text())
    found = found[0] if isinstance(found, list) else found
    found = found["records"][0] if "records" in found else found
    survey = Survey.load(d / "random_walk_survey.h5")
    hyb = depth["hybrid"]["eps_r"]
    grid = np.linspace(np.sqrt(hyb * 0.6), np.sqrt(hyb * 2.0), 8) ** 2
    t = time.perf_counter()
    r = focus_eps(survey, boxes=[tg["box"] for tg in found["targets"]], eps_grid=grid, max_depth_m=0.8)
    wall = time.perf_counter() - t
    truth = depth["eps_r_true"]
    lines = [f"Host CPU: {cpu_name()}; the demo's random-motion survey ({survey.n_traces} traces, poses from the "
             f"fusion), {len(found['targets'])} detected boxes; true eps_r {truth:g}", "",
             "| method | eps_r | error % |", "|---|---|---|"]
    for m in ("net", "fit", "hybrid"):
        e = depth[m]["eps_r"]
        lines.append(f"| {m} (B-scan hyperbolas) | {e:.2f} | {100 * (e - truth) / truth:+.1f} |")
    lines.append(f"| migration focus (3D, {grid.size} eps_r, {wall:.0f} s) | {r['eps_r']:.2f} | "
                 f"{100 * (r['eps_r'] - truth) / truth:+.1f} |")
    write_table(args.out, "focus_eps.md", "\n".join(lines), "eval_focus_eps.py", ["gpr3d_demo"])


if __name__ == "__main__":
    main()
