"""Migration focus (``gpr3d.migration.velocity.focus_eps``): images compared on cells of migrated time or of depth.

The focus is the eps_r whose 3D image of a random-motion survey has the least entropy. On one fixed depth grid a
slower wave (higher eps_r) reads more of the record into the same cells and packs it into fewer of them, so the
entropy drifts down towards the grid's top end; with ``window="time"`` the depth range and depth cell follow the
wave speed and every image holds the same samples on the same number of cells.

Surveys: the analytic forward model (``gpr3d.simulation.forward``; two pipes crossing a 1.2 m square obliquely,
a 1500-trace random walk, 800 MHz, eps_r known) at several eps_r and walk seeds, migrated whole; and, with
``--demo DIR``, the demo's 9011-trace random-motion survey migrated inside its detected boxes (true eps_r 9).
The grid is the same for every survey (3 to 25, 12 values even in slowness: ``focus_eps``'s default), so nothing
is centred on the answer.

    python benchmarks/eval_focus_window.py [--demo gpr3d_demo]
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
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model  # noqa: E402
from gpr3d.simulation.paths import random_walk  # noqa: E402


def walk_survey(eps: float, seed: int) -> Survey:
    scene = ForwardScene(eps_r=eps, pipes=[Pipe((0.1, 0.3, -0.35), (1.1, 0.9, -0.35), 0.03),
                                           Pipe((0.3, 1.1, -0.25), (1.0, 0.1, -0.25), 0.02)])
    traj = random_walk(1500, area=((0.0, 1.2), (0.0, 1.2)), step_m=0.01, seed=seed)
    f, ns, win = 800e6, 256, 16e-9 * np.sqrt(eps / 5.0)
    data = forward_model(scene, traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=0.05, frequency_hz=f,
                         n_samples=ns, time_window_s=win, air_wave=1.0, ground_wave=0.3)
    return Survey(data=data, dt_s=win / ns, positions_xyz=traj.positions_xyz,
                  orientations_quat_wxyz=traj.orientations_quat_wxyz, offset_m=0.05, frequency_hz=f)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--demo", help="a gpr3d demo output folder (random_walk_survey.h5, detections.json)")
    ap.add_argument("--eps", type=float, nargs="+", default=[4.0, 7.0, 9.0, 14.0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 11])
    ap.add_argument("--spacings", type=float, nargs="+", default=[0.05, 0.03])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if not all(np.isfinite(e) and 1.0 <= e <= 80.0 for e in args.eps):
        ap.error(f"--eps must be relative permittivities in 1..80, got {args.eps}")
    if not all(np.isfinite(sp) and 0.005 <= sp <= 0.2 for sp in args.spacings):
        ap.error(f"--spacings must be cell sizes in 0.005..0.2 m, got {args.spacings}")
    if not all(sd >= 0 for sd in args.seeds):
        ap.error(f"--seeds must be whole numbers >= 0, got {args.seeds}")
    cases = []
    if args.demo:
        d = Path(args.demo)
        for name in ("random_walk_survey.h5", "detections.json"):
            if not (d / name).exists():
                ap.error(f"{d / name} is missing: run `gpr3d demo --out {d}` with the dl extra first")
        try:
            boxes = [[float(v) for v in tg["box"]] for tg in json.loads((d / "detections.json").read_text())["targets"]]
        except (ValueError, KeyError, TypeError) as exc:
            ap.error(f"{d / 'detections.json'} is not a gpr3d detect output ({type(exc).__name__}: {exc})")
        cases.append((f"demo survey, {len(boxes)} detected boxes, to 0.8 m", 9.0,
                      lambda: Survey.load(d / "random_walk_survey.h5"), boxes, 0.8))
    for eps in args.eps:
        for seed in args.seeds:
            cases.append((f"forward model, walk seed {seed}, to 0.5 m", eps,
                          lambda eps=eps, seed=seed: walk_survey(eps, seed), None, 0.5))
    rows = ["| survey | true eps_r | cell (m) | window | eps_r found | error % | at grid edge | s |",
            "|---|---|---|---|---|---|---|---|"]
    errs = {}
    for name, truth, make, boxes, depth in cases:
        survey = make()
        for sp in args.spacings:
            for window in ("depth", "time"):
                t = time.perf_counter()
                r = focus_eps(survey, boxes=boxes, spacing_m=sp, max_depth_m=depth, window=window)
                wall = time.perf_counter() - t
                e = 100 * (r["eps_r"] - truth) / truth
                errs.setdefault((sp, window), []).append(abs(e))
                rows.append(f"| {name} | {truth:g} | {sp:g} | {window} | {r['eps_r']:.2f} | {e:+.1f} | "
                            f"{'yes' if r['at_edge'] else 'no'} | {wall:.0f} |")
                print(rows[-1], flush=True)
    rows += ["", "| cell (m) | window | median abs error % | worst abs error % |", "|---|---|---|---|"]
    for (sp, window), e in errs.items():
        rows.append(f"| {sp:g} | {window} | {np.median(e):.1f} | {np.max(e):.1f} |")
    head = f"Host CPU: {cpu_name()}; eps_r grid 3 to 25 (12 values even in sqrt(eps_r)), aperture 50 deg"
    write_table(args.out, "focus_window.md", head + "\n\n" + "\n".join(rows), "eval_focus_window.py",
                sys.argv[1:] if argv is None else list(argv))


if __name__ == "__main__":
    main()
