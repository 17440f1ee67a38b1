"""3D reconstruction over random forward-model scenes (issue 11, item 3): distributions of completeness,
position, orientation, endpoint error, excess length and false targets.

Each scene, from its seed, is one of two kinds:

* ``utility`` (two in three): a 3 m x 3 m patch of soil (eps_r 4-20, 400-600 MHz), two to four steel or PVC
  pipes 0.2-1.5 m deep (top), 1.2-2.6 m long in random directions, an L-bend (two legs meeting at a corner) in
  half of them, a crossing at another depth in half, 20-60 clutter scatterers and noise;
* ``slab``: a 1.6 m x 1.6 m concrete slab (eps_r 5-10, 1.2-2 GHz) with a two-layer rebar mat (bars along x over
  bars along y, 15-20 cm spacing, 4-8 cm cover) and in half of them a conduit below it.

Each is surveyed by a cart's random walk (10,000 traces; every 2 cm of path on soil, 1 cm on the slab),
forward-modelled (``gpr3d.simulation.forward``), and reconstructed by ``gpr3d.migration.reconstruct`` with the
true eps_r (2 cm voxels on soil, 1 cm on the slab). Scoring (``gpr3d.migration.metrics.evaluate_targets``): per
true pipe or bar (its top line), completeness, position and depth error, orientation, endpoint error (how far
the reconstruction's ends lie from the true ends, over- or undershooting); per scene, excess length (extracted
line length lying > 10 cm from every true target, over the true length) and false targets (lines, and points
far from every truth line). Point targets on a true bar count towards its completeness (a rebar found as points).

Development used seeds 100-119; the table reports ``--seeds`` (default 0-23), which nothing was tuned on.

    python benchmarks/eval_scenes.py [--seeds 0-23] [--json out.json] [--no-coarse-to-fine]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.migration.metrics import evaluate_targets, truth_lines_from_pipes  # noqa: E402
from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct  # noqa: E402
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model  # noqa: E402
from gpr3d.simulation.paths import random_walk  # noqa: E402

C0 = 299792458.0


def _pipe_at(rng, area, depth, radius, length):
    """A straight pipe (top at ``depth``) of about ``length`` in a random direction, inside ``area``."""
    (x0, x1), (y0, y1) = area
    for _ in range(100):
        ang = rng.uniform(0, np.pi)
        d = np.array([np.cos(ang), np.sin(ang)])
        c = np.array([rng.uniform(x0 + 0.4, x1 - 0.4), rng.uniform(y0 + 0.4, y1 - 0.4)])
        a, b = c - d * length / 2, c + d * length / 2
        if all(x0 + 0.15 <= p[0] <= x1 - 0.15 and y0 + 0.15 <= p[1] <= y1 - 0.15 for p in (a, b)):
            z = -(depth + radius)
            return Pipe((a[0], a[1], z), (b[0], b[1], z), radius)
    return None


def make_scene(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    if seed % 3 != 2:  # utility
        area = ((0.0, 3.0), (0.0, 3.0))
        eps = float(rng.uniform(4, 20))
        f = float(rng.uniform(400e6, 600e6))
        pipes = []
        for _ in range(int(rng.integers(2, 5))):
            p = _pipe_at(rng, area, rng.uniform(0.2, 1.5), rng.uniform(0.02, 0.08), rng.uniform(1.2, 2.6))
            if p is not None:
                pipes.append(p)
        if rng.random() < 0.5:  # an L-bend: a second leg from the first pipe's end at 60-120 deg
            base = pipes[0]
            a, b = np.array(base.p0[:2]), np.array(base.p1[:2])
            d = (b - a) / np.linalg.norm(b - a)
            ang = rng.uniform(np.radians(60), np.radians(120)) * rng.choice([-1, 1])
            e = np.array([d[0] * np.cos(ang) - d[1] * np.sin(ang), d[0] * np.sin(ang) + d[1] * np.cos(ang)])
            for length in np.linspace(1.4, 0.6, 5):
                c = b + e * length
                if 0.15 <= c[0] <= 2.85 and 0.15 <= c[1] <= 2.85:
                    pipes.append(Pipe(base.p1, (c[0], c[1], base.p1[2]), base.radius_m))
                    break
        if rng.random() < 0.5:  # a crossing: a pipe across the first one's middle, at least 0.2 m deeper/shallower
            base = pipes[0]
            mid = 0.5 * (np.array(base.p0[:2]) + np.array(base.p1[:2]))
            dep = -base.p0[2] - base.radius_m
            dep2 = dep + 0.3 if dep < 0.9 else dep - 0.3
            d = np.array(base.p1[:2]) - np.array(base.p0[:2])
            d = np.array([-d[1], d[0]]) / np.linalg.norm(d)
            a, b = np.clip(mid - 0.9 * d, 0.15, 2.85), np.clip(mid + 0.9 * d, 0.15, 2.85)
            r = float(rng.uniform(0.02, 0.05))
            pipes.append(Pipe((a[0], a[1], -(dep2 + r)), (b[0], b[1], -(dep2 + r)), r))
        clutter, noise, step, spacing = int(rng.integers(20, 61)), float(rng.uniform(0.005, 0.02)), 0.02, 0.02
        kind = "utility"
    else:  # slab with a two-layer rebar mat
        area = ((0.0, 1.6), (0.0, 1.6))
        eps = float(rng.uniform(5, 10))
        f = float(rng.uniform(1.2e9, 2.0e9))
        r = float(rng.uniform(0.006, 0.01))
        cover = float(rng.uniform(0.04, 0.08))
        s1, s2 = rng.uniform(0.15, 0.2, 2)
        pipes = []
        z1 = -(cover + r)
        for y in np.arange(0.25, 1.36, s1):
            pipes.append(Pipe((0.2, y, z1), (1.4, y, z1), r))
        z2 = z1 - 2 * r
        for x in np.arange(0.25, 1.36, s2):
            pipes.append(Pipe((x, 0.2, z2), (x, 1.4, z2), r))
        if rng.random() < 0.5:
            dep = float(rng.uniform(0.15, 0.25))
            ang = rng.uniform(0, np.pi)
            c = np.array([0.8, 0.8])
            d = np.array([np.cos(ang), np.sin(ang)]) * 0.55
            pipes.append(Pipe((*(c - d), -(dep + 0.015)), (*(c + d), -(dep + 0.015)), 0.015))
        clutter, noise, step, spacing = int(rng.integers(10, 31)), float(rng.uniform(0.005, 0.015)), 0.01, 0.01
        kind = "slab"
    deepest = max(-p.p0[2] + p.radius_m for p in pipes)
    v = C0 / math.sqrt(eps)
    window = 2 * (deepest + 0.25) / v + 3.0 / f
    return {"kind": kind, "seed": seed, "area": area, "eps_r": eps, "frequency_hz": f, "pipes": pipes,
            "clutter": clutter, "noise": noise, "step_m": step, "spacing_m": spacing, "window_s": window,
            "max_depth_m": deepest + 0.15}


def scene_survey(spec: dict, n_traces: int = 10_000) -> Survey:
    """The survey of ``spec``: a cart's random walk over its area, forward-modelled (raw: time zero and background
    left to ``reconstruct``)."""
    sc = ForwardScene(eps_r=spec["eps_r"], conductivity_s_m=0.002, pipes=spec["pipes"])
    walk = random_walk(n_traces, area=spec["area"], step_m=spec["step_m"], turn_rate=0.1, seed=spec["seed"])
    offset = 0.1 if spec["kind"] == "utility" else 0.04
    data = forward_model(sc, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=offset,
                         frequency_hz=spec["frequency_hz"], n_samples=512, time_window_s=spec["window_s"],
                         air_wave=1.0, ground_wave=0.5, clutter=spec["clutter"], noise=spec["noise"],
                         seed=spec["seed"])
    return Survey(data=data, dt_s=spec["window_s"] / 512, positions_xyz=walk.positions_xyz,
                  orientations_quat_wxyz=walk.orientations_quat_wxyz, offset_m=offset,
                  frequency_hz=spec["frequency_hz"], eps_r=spec["eps_r"])


def run_scene(spec: dict, n_traces: int = 10_000, **settings):
    """The scene's survey reconstructed at ``reconstruct``'s defaults (``settings``: other ones), scored; returns the
    evaluation and the reconstruction's seconds."""
    s = scene_survey(spec, n_traces)
    t = time.perf_counter()
    rec = reconstruct(s, ReconstructConfig(eps_r=spec["eps_r"], spacing_m=spec["spacing_m"],
                                           max_depth_m=spec["max_depth_m"], **settings))
    wall = time.perf_counter() - t
    ev = evaluate_targets(rec.targets, truth_lines_from_pipes(spec["pipes"]))
    return ev, wall


def _pct(vals, q):
    return float(np.percentile(vals, q)) if len(vals) else math.nan


def parse_seeds(text: str) -> list[int]:
    """``"A-B"`` (both ends included) or ``"A,B,..."``: the scene seeds (ValueError otherwise)."""
    if "-" in text:
        a, b = (int(v) for v in text.split("-"))
        return list(range(a, b + 1))
    return [int(v) for v in text.split(",")]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-23", help="scene seeds: A-B or a comma list (default 0-23)")
    ap.add_argument("--traces", type=int, default=10_000)
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-coarse-to-fine", action="store_true", help="migrate every voxel (reconstruct's default "
                    "is coarse-to-fine)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError:
        ap.error(f"--seeds must be A-B or a comma list of whole numbers, got {args.seeds!r}")
    if not seeds or args.traces < 1000:
        ap.error("--seeds must name at least one scene and --traces be >= 1000")
    rows, scenes = [], []
    for seed in seeds:
        spec = make_scene(seed)
        ev, wall = run_scene(spec, args.traces, **({"coarse_to_fine": False} if args.no_coarse_to_fine else {}))
        for r in ev["truth"]:
            rows.append({"kind": spec["kind"], "seed": seed, **{k: v for k, v in r.items() if k != "samples"}})
        scenes.append({"kind": spec["kind"], "seed": seed, "false_lines": ev["false_lines"],
                       "false_points": ev["false_points"], "excess_frac": ev["excess_fraction"],
                       "true_length_m": ev["true_length_m"], "wall_s": wall, "eps_r": spec["eps_r"],
                       "frequency_hz": spec["frequency_hz"], "n_truth": len(ev["truth"])})
        found = [r for r in ev["truth"] if "position_error_m" in r]
        print(f"seed {seed:3d} {spec['kind']:8s} eps {spec['eps_r']:5.1f} {spec['frequency_hz'] / 1e6:5.0f} MHz: "
              f"{len(found)}/{len(ev['truth'])} found, completeness median "
              f"{np.median([r['completeness'] for r in ev['truth']]):.2f}, excess {ev['excess_fraction'] * 100:.0f} %, "
              f"false lines {ev['false_lines']}, points {ev['false_points']} ({wall:.1f} s)", flush=True)
    lines = [f"Host CPU: {cpu_name()}, {os.environ['NUMBA_NUM_THREADS']} threads; {len(scenes)} scenes (seeds "
             f"{args.seeds}), {args.traces} traces each; {len(rows)} true pipes and bars; "
             f"{'every voxel migrated' if args.no_coarse_to_fine else 'coarse-to-fine (the default)'}", "",
             "| set | quantity | median | 10th pct | 90th pct | goal |", "|---|---|---|---|---|---|"]

    def add(kind, name, vals, goal, scale=1.0):
        v = [x * scale for x in vals if x == x]
        lines.append(f"| {kind} | {name} | {_pct(v, 50):.2f} | {_pct(v, 10):.2f} | {_pct(v, 90):.2f} | {goal} |")

    for kind in ("all", "utility", "slab"):
        rs = [r for r in rows if kind == "all" or r["kind"] == kind]
        ss = [s for s in scenes if kind == "all" or s["kind"] == kind]
        if not rs:
            continue
        add(kind, "completeness", [r["completeness"] for r in rs], ">= 0.95")
        add(kind, "position error (cm)", [r.get("position_error_m", math.nan) for r in rs], "<= 2", 100)
        add(kind, "depth error (cm)", [r.get("depth_error_m", math.nan) for r in rs], "-", 100)
        add(kind, "orientation error (deg)", [r.get("orientation_error_deg", math.nan) for r in rs], "<= 2")
        add(kind, "endpoint error (cm)", [r.get("endpoint_error_m", math.nan) for r in rs], "-", 100)
        add(kind, "excess length (% of true length, per scene)", [s["excess_frac"] for s in ss], "<= 5", 100)
        add(kind, "false lines per scene", [s["false_lines"] for s in ss], "<= 1")
        add(kind, "false points per scene", [s["false_points"] for s in ss], "-")
        missed = sum("position_error_m" not in r for r in rs)
        lines.append(f"| {kind} | true targets not found at all | {missed} of {len(rs)} | | | |")
    walls = [s["wall_s"] for s in scenes]
    lines += ["", f"reconstruct per scene: median {np.median(walls):.1f} s (migration, envelope, targets)"]
    write_table(args.out, "scenes.md", "\n".join(lines), "eval_scenes.py", argv)
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "scenes": scenes}, indent=1, default=float))


if __name__ == "__main__":
    main()
