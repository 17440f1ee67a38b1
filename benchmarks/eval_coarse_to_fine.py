"""Coarse-to-fine imaging against migrating every voxel (issue 32, item 2): the same targets, for how much less work.

Scenes: ``eval_scenes.py``'s random forward-model scenes (utility patches at 400-600 MHz with clutter and noise,
concrete slabs with rebar mats at 1.2-2 GHz), 10,000 traces each along a cart's random walk, and the 8000-trace
survey of ``bench_stages.py`` (the L-pipe scene, no noise). Each is reconstructed at ``reconstruct``'s defaults
(the true eps_r given; 2 cm voxels on soil, 1 cm on the slabs, the whole record's depth) with every voxel
migrated (``coarse_to_fine=False``) and with coarse-to-fine (the default since the thirty-third session) at each
``--levels`` value
(``refine_level``, a share of the target threshold; where the coarse pass marks more than
``refine.MAX_REFINED`` of the voxels, every voxel is migrated after it). Per scene and setting: the migration's seconds, the share of voxels refined, and the
targets scored against the truth (``gpr3d.migration.metrics.evaluate_targets``: completeness, position and depth
error, false targets) beside the full image's; the largest change of the envelope on the voxels where the full
image's reaches the targets' threshold (``threshold`` x the ridge map's 99.5th percentile), as a share of its
peak.

Development used seeds 100-105; the table reports ``--seeds`` (default 0-11), which nothing was tuned on.

    python benchmarks/eval_coarse_to_fine.py [--seeds 0-11] [--levels 0.25,0.5] [--margins columns,0.5,1]
        [--coarse-wavelengths 0.333] [--max-stride 4] [--max-trace-step 4] [--threads 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, threads_from_argv, write_table  # noqa: E402

if __name__ == "__main__":  # numba reads the thread count at import
    threads_from_argv()

import numpy as np  # noqa: E402

from eval_scenes import make_scene, scene_survey  # noqa: E402

from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.migration.config import ReconstructConfig  # noqa: E402
from gpr3d.migration.metrics import evaluate_targets, truth_lines_from_pipes  # noqa: E402
from gpr3d.migration.reconstruct import reconstruct  # noqa: E402
from gpr3d.simulation.forward import forward_model  # noqa: E402


def stages_survey():
    """``bench_stages.py``'s 8000-trace L-pipe survey and its pipes."""
    from bench_reconstruct import cart_path
    from eval_reconstruction import EPS, F, NS, OFFSET, WINDOW, scene

    traj = cart_path(8000)
    sc = scene()
    data = forward_model(sc, traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F,
                         n_samples=NS, time_window_s=WINDOW, air_wave=1.0, ground_wave=0.5)
    s = Survey(data=data, dt_s=WINDOW / NS, positions_xyz=traj.positions_xyz,
               orientations_quat_wxyz=traj.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F, eps_r=EPS)
    return s, sc.pipes


def score(rec, pipes) -> dict:
    ev = evaluate_targets(rec.targets, truth_lines_from_pipes(pipes))
    rows = ev["truth"]
    comp = float(np.mean([r["completeness"] for r in rows])) if rows else float("nan")
    pos = [r["position_error_m"] for r in rows if r.get("position_error_m") is not None]
    dep = [r["depth_error_m"] for r in rows if r.get("depth_error_m") is not None]
    return {"completeness": comp, "position_m": float(np.mean(pos)) if pos else float("nan"),
            "depth_m": float(np.mean(dep)) if dep else float("nan"), "false": ev["false_targets"],
            "n": len(rec.targets)}


def target_list(rec):
    """The targets as compared between two images: kind and points to the millimetre."""
    return [(t.kind, np.round(np.asarray(t.points_xyz, float), 3).tolist()) for t in rec.targets]


class refine_mode:
    """Within it, coarse-to-fine refines depth ranges with ``margin`` wavelengths, or whole columns (None)."""

    def __init__(self, margin):
        self.margin = margin

    def __enter__(self):
        import functools

        from gpr3d.migration import refine

        self.saved = refine.refined_adjoint
        refine.refined_adjoint = functools.partial(self.saved, depth_margin=self.margin)

    def __exit__(self, *exc):
        from gpr3d.migration import refine

        refine.refined_adjoint = self.saved


def compare(name, s, pipes, spacing, levels, log, margins=(None,)):
    out = []
    t = time.perf_counter()
    full = reconstruct(s, ReconstructConfig(eps_r=s.eps_r, spacing_m=spacing, coarse_to_fine=False))
    full_s = time.perf_counter() - t
    ref = float(np.percentile(full.envelope.max(axis=2), 99.5))
    near = full.envelope >= full.config["threshold"] * ref
    peak = float(full.envelope.max())
    sf = score(full, pipes)
    out.append({"scene": name, "setting": "every voxel", "migrate_s": full.timings_s["migrate"], "wall_s": full_s,
                "fraction": 1.0, "env_change": 0.0, "same": True, **sf})
    for lv in levels:
        for margin in margins:
            with refine_mode(margin):
                t = time.perf_counter()
                r = reconstruct(s, ReconstructConfig(eps_r=s.eps_r, spacing_m=spacing, coarse_to_fine=True,
                                                     refine_level=lv))
                wall = time.perf_counter() - t
            assert r.grid == full.grid
            d = float(np.abs(r.envelope - full.envelope)[near].max()) / peak if near.any() else 0.0
            how = "whole columns" if margin is None else f"depth ranges +- {margin:g} wavelength"
            out.append({"scene": name, "setting": f"coarse-to-fine {lv:g}, {how}", "migrate_s": r.timings_s["migrate"],
                        "wall_s": wall, "fraction": r.refine.get("refined_fraction", 1.0),
                        "stride": r.refine.get("stride", 1), "env_change": d,
                        "trace_step": (f"{r.refine['thinned']['trace_step']}, completed" if "thinned" in r.refine
                                       else str(r.refine.get("coarse_trace_step", 1))),
                        "same": target_list(r) == target_list(full), **score(r, pipes)})
    for row in out:
        log(f"{row['scene']:>10s} {row['setting']:>20s} migrate {row['migrate_s']:6.2f} s  refined "
            f"{row['fraction']:.3f} (coarse trace step {row.get('trace_step', '-')})  completeness "
            f"{row['completeness']:.3f}  pos {row['position_m']:.3f}  false {row['false']}  env change "
            f"{row['env_change']:.4f}")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-11")
    ap.add_argument("--levels", default="0.5")
    ap.add_argument("--margins", default="columns,0.5,1",
                    help="how coarse-to-fine refines: 'columns' (whole columns) or a depth range's margin in "
                         "wavelengths, comma-separated")
    ap.add_argument("--coarse-wavelengths", type=float, default=None,
                    help="the coarse columns' spacing in wavelengths (default: refine.COARSE_WAVELENGTHS)")
    ap.add_argument("--max-stride", type=int, default=None, help="the coarse stride's cap (default: refine.MAX_STRIDE)")
    ap.add_argument("--max-trace-step", type=int, default=None,
                    help="the coarse pass's trace thinning cap (default: refine.MAX_TRACE_STEP; 1: every trace)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-stages-survey", action="store_true")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if "-" in args.seeds:
        a, b = (int(v) for v in args.seeds.split("-"))
        seeds = list(range(a, b + 1))
    else:
        seeds = [int(v) for v in args.seeds.split(",")]
    try:
        levels = [float(v) for v in args.levels.split(",")]
        margins = [None if v == "columns" else float(v) for v in args.margins.split(",")]
    except ValueError:
        ap.error("--levels takes numbers and --margins numbers or 'columns', comma-separated")
    if not all(0 < v <= 1 for v in levels) or not all(m is None or m >= 0 for m in margins):
        ap.error("--levels must lie in (0, 1] and --margins be >= 0 (or 'columns')")
    from gpr3d.migration import refine

    if args.coarse_wavelengths is not None:
        if not 0 < args.coarse_wavelengths <= 2:
            ap.error("--coarse-wavelengths must lie in (0, 2]")
        refine.COARSE_WAVELENGTHS = args.coarse_wavelengths
    if args.max_stride is not None:
        if args.max_stride < 1:
            ap.error("--max-stride must be >= 1")
        refine.MAX_STRIDE = args.max_stride
    if args.max_trace_step is not None:
        if args.max_trace_step < 1:
            ap.error("--max-trace-step must be >= 1")
        refine.MAX_TRACE_STEP = args.max_trace_step
    rows = []

    def log(msg):
        print(msg, flush=True)

    if not args.no_stages_survey:
        s, pipes = stages_survey()
        rows += compare("L-pipes", s, pipes, 0.02, levels, log, margins)
    for seed in seeds:
        spec = make_scene(seed)
        rows += compare(f"{spec['kind']} {seed}", scene_survey(spec), spec["pipes"], spec["spacing_m"], levels, log,
                        margins)

    settings = list(dict.fromkeys(r["setting"] for r in rows))
    lines = [f"Host CPU: {cpu_name()}, {args.threads} threads; `reconstruct` (true eps_r; 2 cm voxels on soil, 1 cm on "
             f"slabs; whole record) with every voxel migrated (`coarse_to_fine=False`), and coarse-to-fine (the "
             f"default) at each `refine_level`, coarse columns {refine.COARSE_WAVELENGTHS:.3g} wavelength apart "
             f"(stride at most {refine.MAX_STRIDE}), the coarse pass from every m-th trace (m at most "
             f"{refine.MAX_TRACE_STEP}: `refine.coarse_trace_step`), on the 8000-trace L-pipe survey and eval_scenes seeds {args.seeds} "
             "(10,000 traces each)", "",
             "| setting | migration s (sum) | x every voxel | refined share (mean) | completeness (mean) | "
             "position err m (mean) | false targets (sum) | envelope change where targets are (max, of peak) | "
             "scenes with the same targets (to the mm) |",
             "|---|---|---|---|---|---|---|---|---|"]
    base = sum(r["migrate_s"] for r in rows if r["setting"] == "every voxel")
    for st in settings:
        rs = [r for r in rows if r["setting"] == st]
        mig = sum(r["migrate_s"] for r in rs)
        lines.append(f"| {st} | {mig:.1f} | {mig / base:.2f} | {np.mean([r['fraction'] for r in rs]):.3f} | "
                     f"{np.nanmean([r['completeness'] for r in rs]):.3f} | "
                     f"{np.nanmean([r['position_m'] for r in rs]):.3f} | {sum(r['false'] for r in rs)} | "
                     f"{max(r['env_change'] for r in rs):.4f} | {sum(r['same'] for r in rs)} of {len(rs)} |")
    lines += ["", "| scene | setting | migration s | coarse pass: every m-th trace | refined share | completeness | "
              "position err m | false | targets | envelope change | same targets |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['setting']} | {r['migrate_s']:.2f} | {r.get('trace_step', '-')} | "
                     f"{r['fraction']:.3f} | "
                     f"{r['completeness']:.3f} | {r['position_m']:.3f} | {r['false']} | {r['n']} | "
                     f"{r['env_change']:.4f} | {'yes' if r['same'] else 'no'} |")
    write_table(args.out, "coarse_to_fine.md", "\n".join(lines), "eval_coarse_to_fine.py", argv)


if __name__ == "__main__":
    main()
