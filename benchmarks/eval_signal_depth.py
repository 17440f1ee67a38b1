"""A depth range that follows the data (issue 32, item 2): ``reconstruct``'s grid ending where the signal ends
(:mod:`gpr3d.processing.signal`) against the whole record's depth: how much shallower, how much less migration,
and whether the targets and the image where they are stay the same.

Surveys:

- ``eval_scenes.py``'s random forward-model scenes (``--seeds``, default 0-11; utility patches at 400-600 MHz
  with clutter and receiver noise, concrete slabs with rebar mats at 1.2-2 GHz), 10,000 traces each along a cart's
  random walk, scored against their pipes (``gpr3d.migration.metrics.evaluate_targets``);
- ``bench_stages.py``'s 8000-trace L-pipe survey as it is (no noise: the signal's tails reach the record's end,
  nothing may be cut), and with white receiver noise of 1 % of its peak added;
- with ``--real`` (the folder present), the 25-line Sensors & Software 100 MHz grid of ``real_grid.py`` at its
  settings (0.1 m voxels, eps_r from the lines' hybrid estimates), the whole record against the signal's depth:
  no truth, so the two target lists are compared with each other.

Each at ``reconstruct``'s defaults (the true eps_r given; 2 cm voxels on soil, 1 cm on slabs) with
``signal_depth=False`` (the whole record, the default) and with ``signal_depth=True``. Per survey: the record's and
the signal's depth, the migration's seconds (the signal's including its coarse whole-record fold), the targets'
scores, and the largest change of the envelope on the voxels where the whole record's reaches the targets'
threshold (``threshold`` x the 99.5th percentile of its column maxima), as a share of its peak.

    python benchmarks/eval_signal_depth.py [--seeds 0-11] [--real] [--threads 2]
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

from eval_coarse_to_fine import score, stages_survey  # noqa: E402
from eval_scenes import make_scene, scene_survey  # noqa: E402

from gpr3d.core.timing import collect  # noqa: E402
from gpr3d.migration.config import ReconstructConfig  # noqa: E402
from gpr3d.migration.reconstruct import reconstruct  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed(s, cfg):
    """The reconstruction, its migration seconds (with the signal's search and coarse fold) and wall seconds."""
    t = time.perf_counter()
    with collect(compile_times=False) as c:
        rec = reconstruct(s, cfg)
    wall = time.perf_counter() - t
    mig = sum(c.seconds.get(k, 0.0) for k in ("migrate", "signal depth", "fold max"))
    return rec, mig, wall


def compare(name, s, pipes, cfg: ReconstructConfig, log):
    from dataclasses import replace

    full, full_mig, full_wall = timed(s, replace(cfg, signal_depth=False))
    cut, cut_mig, cut_wall = timed(s, replace(cfg, signal_depth=True))
    nd = cut.grid.nd
    assert cut.grid.nd <= full.grid.nd and (cut.grid.nx, cut.grid.ny) == (full.grid.nx, full.grid.ny)
    ref = float(np.percentile(full.envelope.max(axis=2), 99.5))
    near = full.envelope[:, :, :nd] >= full.config["threshold"] * ref
    peak = float(full.envelope.max())
    change = float(np.abs(cut.envelope - full.envelope[:, :, :nd])[near].max()) / peak if near.any() else 0.0
    # targets of the whole record below the signal's depth (none may be lost there: they would be noise's)
    deeper = sum(1 for t in full.targets if max(p[2] for p in t.points_xyz) > cut.grid.depth[-1])
    same = [(t.kind, np.round(t.points_xyz, 2).tolist()) for t in cut.targets] == \
           [(t.kind, np.round(t.points_xyz, 2).tolist()) for t in full.targets]
    row = {"survey": name, "record_m": full.grid.depth[-1], "depth_m": cut.grid.depth[-1],
           "why": cut.depth.get("why", ""), "full_s": full_mig, "cut_s": cut_mig, "full_wall": full_wall,
           "cut_wall": cut_wall, "change": change, "deeper": deeper, "same": same,
           "full": score(full, pipes) if pipes is not None else {"n": len(full.targets)},
           "cut": score(cut, pipes) if pipes is not None else {"n": len(cut.targets)}}
    log(f"{name:>14s}  depth {row['record_m']:.2f} -> {row['depth_m']:.2f} m  migrate {full_mig:6.2f} -> "
        f"{cut_mig:6.2f} s  targets {row['full']['n']} / {row['cut']['n']} same {same}  env change {change:.4f}")
    return row


def real_grid(log):
    from real_grid import host_eps_r

    import gpr3d
    from gpr3d.core.gridsurvey import assemble_grid

    folder = ROOT.parent / "shared/data/real/gpro_sns_100MHz_grid"
    files = sorted(folder.glob("XLINE*.DT1"))
    if len(files) < 2:
        log(f"{folder}: not here, the real grid left out")
        return []
    lines = [gpr3d.read(f).time_zero(method="peak").dewow().remove_background() for f in files]
    grid_survey = assemble_grid(lines, names=[f.name for f in files], line_spacing_m=0.2)
    eps, _ = host_eps_r(files)
    v = 299792458.0 / np.sqrt(eps)
    cfg = ReconstructConfig(eps_r=eps, spacing_m=0.1, time_zero="none", remove_background=False,
                            min_target_depth_m=0.5 * v / 100e6)
    return [compare("real 100 MHz grid", grid_survey, None, cfg, log)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-11")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--real", action="store_true", help="the real 100 MHz grid too (../shared/data/real)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b or a) + 1))

    def log(msg):
        print(msg, flush=True)

    rows = []
    s, pipes = stages_survey()
    rows.append(compare("L-pipes", s, pipes, ReconstructConfig(eps_r=s.eps_r, spacing_m=0.02), log))
    rng = np.random.default_rng(0)
    noisy = s.replace(data=s.data + rng.normal(0, 0.01 * np.abs(s.data).max(), s.data.shape).astype(np.float32))
    rows.append(compare("L-pipes, 1 % noise", noisy, pipes, ReconstructConfig(eps_r=s.eps_r, spacing_m=0.02), log))
    for seed in seeds:
        spec = make_scene(seed)
        rows.append(compare(f"{spec['kind']} {seed}", scene_survey(spec), spec["pipes"],
                            ReconstructConfig(eps_r=spec["eps_r"], spacing_m=spec["spacing_m"]), log))
    if args.real:
        rows += real_grid(log)

    def sc(r, key, fmt):
        v = r[key].get(fmt[0])
        return "-" if v is None else format(v, fmt[1])

    synth = [r for r in rows if r["full"].get("completeness") is not None]
    full_s, cut_s = sum(r["full_s"] for r in rows), sum(r["cut_s"] for r in rows)
    lines = [f"Host CPU: {cpu_name()}, {args.threads} threads; `reconstruct` at its defaults (true eps_r; 2 cm voxels "
             f"on soil, 1 cm on slabs) over the whole record (`signal_depth=False`, the default) and to the "
             f"signal's end (`--signal-depth`); the 8000-trace L-pipe survey as it is and with 1 % noise, eval_scenes seeds {args.seeds} "
             f"(10,000 traces each){', the real 100 MHz grid' if args.real else ''}", "",
             f"Migration (with the signal's search and the coarse whole-record fold): {full_s:.1f} s -> {cut_s:.1f} s "
             f"({cut_s / full_s:.2f}x) over all {len(rows)} surveys; targets the same (to the centimetre) in "
             f"{sum(r['same'] for r in rows)} of {len(rows)}; mean completeness "
             f"{np.mean([r['full']['completeness'] for r in synth]):.3f} -> "
             f"{np.mean([r['cut']['completeness'] for r in synth]):.3f}, false targets "
             f"{sum(r['full']['false'] for r in synth)} -> {sum(r['cut']['false'] for r in synth)}; the largest "
             f"envelope change where targets are {max(r['change'] for r in rows):.4f} of the peak", "",
             "| survey | record depth m | signal depth m | migrate s, whole | migrate s, signal | x | targets whole / "
             "signal | same | below the signal's depth | completeness whole / signal | false whole / signal | "
             "envelope change | why |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['survey']} | {r['record_m']:.2f} | {r['depth_m']:.2f} | {r['full_s']:.2f} | "
                     f"{r['cut_s']:.2f} | {r['cut_s'] / r['full_s']:.2f} | {r['full']['n']} / {r['cut']['n']} | "
                     f"{'yes' if r['same'] else 'no'} | {r['deeper']} | {sc(r, 'full', ('completeness', '.3f'))} / "
                     f"{sc(r, 'cut', ('completeness', '.3f'))} | {sc(r, 'full', ('false', 'd'))} / "
                     f"{sc(r, 'cut', ('false', 'd'))} | {r['change']:.4f} | {r['why']} |")
    write_table(args.out, "signal_depth.md", "\n".join(lines), "eval_signal_depth.py", argv)


if __name__ == "__main__":
    main()
