"""An aperture radius against the cone alone (issue 32, item 2): the same targets, for how much less migration.

``reconstruct`` limits each trace's reach by a cone (``aperture_deg``, 50 deg from the vertical): at depth d a trace
adds to the columns within d tan(50 deg) of its tx-rx midpoint, so a deep voxel sums far more traces than a shallow
one (1.76 m down, those within 2.1 m). ``aperture_m`` cuts the cone off at a horizontal radius, as the plain
aperture-limited back projection of ``bench_stages.py`` does (1 m). This runs ``reconstruct`` at its defaults with
the cone alone and with each radius of ``--radii`` (metres, ``1m``, or centre wavelengths in the host, ``5wl``), on
the scenes of ``eval_coarse_to_fine.py`` (eval_scenes' random forward-model scenes, 10,000 traces each, and the
8000-trace L-pipe survey), and reports per scene and setting: the migration's seconds, the targets scored against
the truth (completeness, position error, false targets), and the largest change of the envelope, each image's
scaled by its own reference level (the targets' 99.5th percentile of the ridge map), on the voxels where the
cone-only image reaches the targets' threshold.

Development used seeds 100-105; the table reports ``--seeds`` (default 0-11), which nothing was tuned on.

    python benchmarks/eval_aperture.py [--seeds 0-11] [--radii 1m,5wl] [--threads 2] [--out DIR]
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

from eval_coarse_to_fine import score, stages_survey, target_list  # noqa: E402
from eval_scenes import make_scene, parse_seeds, scene_survey  # noqa: E402

from gpr3d.core.units import velocity_from_eps_r  # noqa: E402
from gpr3d.migration.config import ReconstructConfig  # noqa: E402
from gpr3d.migration.reconstruct import reconstruct  # noqa: E402


def parse_radius(text: str) -> tuple[float, str]:
    """``"1m"`` -> (1.0, "m"); ``"5wl"`` -> (5.0, "wl")."""
    for unit in ("wl", "m"):
        if text.endswith(unit):
            v = float(text[: -len(unit)])
            if not v > 0:
                raise ValueError(text)
            return v, unit
    raise ValueError(text)


def radius_m(value: float, unit: str, s) -> float:
    if unit == "m":
        return value
    return value * velocity_from_eps_r(s.eps_r) / s.frequency_hz


def level(rec) -> float:
    """The image's reference level as the targets see it: the 99.5th percentile of its ridge map."""
    return float(np.percentile(rec.envelope.max(axis=2), 99.5))


def warm_up():
    """The tiled kernel compiled (or loaded from numba's cache) before anything is timed, as the warm-up of
    ``gpr3d.cli._warm`` builds it."""
    from gpr3d.migration import _kernels

    _kernels.tiled_adjoint(_kernels.read_path(), True)


def compare(name, s, pipes, spacing, radii, log):
    out = []
    t = time.perf_counter()
    full = reconstruct(s, ReconstructConfig(eps_r=s.eps_r, spacing_m=spacing))
    wall = time.perf_counter() - t
    ref = level(full)
    near = full.envelope >= full.config["threshold"] * ref
    out.append({"scene": name, "setting": "cone alone (50 deg)", "radius_m": float("nan"),
                "migrate_s": full.timings_s["migrate"], "wall_s": wall, "env_change": 0.0, "same": True,
                **score(full, pipes)})
    for value, unit in radii:
        r_m = radius_m(value, unit, s)
        t = time.perf_counter()
        r = reconstruct(s, ReconstructConfig(eps_r=s.eps_r, spacing_m=spacing, aperture_m=r_m))
        wall = time.perf_counter() - t
        assert r.grid == full.grid
        d = float(np.abs(r.envelope / level(r) - full.envelope / ref)[near].max()) if near.any() else 0.0
        out.append({"scene": name, "setting": f"radius {value:g} {'m' if unit == 'm' else 'wavelengths'}",
                    "radius_m": r_m, "migrate_s": r.timings_s["migrate"], "wall_s": wall, "env_change": d,
                    "same": target_list(r) == target_list(full), **score(r, pipes)})
    for row in out:
        log(f"{row['scene']:>10s} {row['setting']:>22s} migrate {row['migrate_s']:6.2f} s  "
            f"completeness {row['completeness']:.3f}  pos {row['position_m']:.4f}  false {row['false']}  n {row['n']}  "
            f"env change {row['env_change']:.4f}  same {row['same']}")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-11")
    ap.add_argument("--radii", default="1m,5wl", help="radii, comma-separated: metres ('1m') or centre wavelengths "
                                                       "in the host ('5wl')")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--no-stages-survey", action="store_true")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds)
        radii = [parse_radius(v) for v in args.radii.split(",")]
    except ValueError:
        ap.error("--seeds takes A-B or A,B,...; --radii positive numbers ending in 'm' or 'wl', comma-separated")

    warm_up()
    rows = []

    def log(msg):
        print(msg, flush=True)

    if not args.no_stages_survey:
        s, pipes = stages_survey()
        rows += compare("L-pipes", s, pipes, 0.02, radii, log)
    for seed in seeds:
        spec = make_scene(seed)
        rows += compare(f"{spec['kind']} {seed}", scene_survey(spec), spec["pipes"], spec["spacing_m"], radii, log)

    settings = list(dict.fromkeys(r["setting"] for r in rows))
    lines = [f"Host CPU: {cpu_name()}, {args.threads} threads; `reconstruct` at its defaults (true eps_r; 2 cm voxels "
             "on soil, 1 cm on slabs; whole record; every voxel; 50 deg cone) and with `aperture_m` at each radius, "
             f"on the 8000-trace L-pipe survey and eval_scenes seeds {args.seeds} (10,000 traces each)", "",
             "| setting | migration s (sum) | x cone alone | completeness (mean) | position err m (mean) | "
             "false targets (sum) | targets (sum) | envelope change where targets are (max, of the reference level) | "
             "scenes with the same targets (to the mm) |",
             "|---|---|---|---|---|---|---|---|---|"]
    base = sum(r["migrate_s"] for r in rows if r["setting"] == settings[0])
    for st in settings:
        rs = [r for r in rows if r["setting"] == st]
        mig = sum(r["migrate_s"] for r in rs)
        lines.append(f"| {st} | {mig:.1f} | {mig / base:.2f} | {np.nanmean([r['completeness'] for r in rs]):.3f} | "
                     f"{np.nanmean([r['position_m'] for r in rs]):.4f} | {sum(r['false'] for r in rs)} | "
                     f"{sum(r['n'] for r in rs)} | {max(r['env_change'] for r in rs):.3f} | "
                     f"{sum(r['same'] for r in rs)} of {len(rs)} |")
    lines += ["", "| scene | setting | radius m | migration s | completeness | position err m | false | targets | "
              "envelope change | same targets |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        radius = "-" if np.isnan(r["radius_m"]) else f"{r['radius_m']:.2f}"
        lines.append(f"| {r['scene']} | {r['setting']} | {radius} | {r['migrate_s']:.2f} | "
                     f"{r['completeness']:.3f} | {r['position_m']:.4f} | {r['false']} | {r['n']} | "
                     f"{r['env_change']:.3f} | {'yes' if r['same'] else 'no'} |")
    write_table(args.out, "aperture_radius.md", "\n".join(lines), "eval_aperture.py", argv)


if __name__ == "__main__":
    main()
