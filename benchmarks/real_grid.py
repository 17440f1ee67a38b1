"""The real 25-line grid (issue 12, item 2): C-scans, pseudo-3D and 3D back projection from the same lines.

``../shared/data/real/gpro_sns_100MHz_grid``: a pulseEKKO PRO 100 MHz survey, 25 parallel lines 0.2 m apart,
a trace every 0.05 m, 200 ns (GPR-O's example 1, GPL-3.0). The lines are processed one by one (time zero from
the direct wave, dewow, background removal), put together with ``gpr3d.core.gridsurvey.assemble_grid``
(parallel, all walked the same way: the files' own positions start at 0), and

* C-scans: 8 ns slices of the gridded envelope (``gpr3d.processing.cscan``);
* the host's eps_r: the median over the lines of ``gpr3d depth``'s hybrid estimate (hyperbolas in each line);
* pseudo-3D: each line migrated in 2D (Kirchhoff) and the planes interpolated between lines
  (``reconstruct(method="pseudo3d")``, ``gpr3d reconstruct --method pseudo3d``);
* 3D: ``gpr3d.migration.reconstruct`` (back projection from every trace's position).

Targets come from ``gpr3d.migration.targets.extract_targets`` on both volumes (inside ``reconstruct``). Writes
``docs/figures/real_grid_cscans.png``, ``real_grid_pseudo3d.png``, ``real_grid_3d.png`` and
``benchmarks/results/real_grid.md``.

    python benchmarks/real_grid.py [--data ../shared/data/real/gpro_sns_100MHz_grid]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

import gpr3d  # noqa: E402
from gpr3d.core.gridsurvey import assemble_grid  # noqa: E402
from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct  # noqa: E402
from gpr3d.processing.cscan import cscan  # noqa: E402
from gpr3d.viz._figures import pyplot, save_figure  # noqa: E402
from gpr3d.viz.maps import save_cscan_sheet  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def host_eps_r(files) -> tuple[float, list[float]]:
    """The median over the lines of the hybrid eps_r estimate (``gpr3d depth``'s), and each line's."""
    from gpr3d.pipeline import add_depths, load_models

    det, net = load_models(depth="hybrid")
    per_line = []
    for f in files:
        s = gpr3d.read(f)
        found = det.detect(s, score_threshold=0.5, input_name=str(f))
        add_depths(s, found, "hybrid", net, None)
        if "permittivity" in found and np.isfinite(found["permittivity"]["eps_r"]):
            per_line.append(float(found["permittivity"]["eps_r"]))
    return float(np.median(per_line)), per_line


def top_view(ax, env, grid, targets, title):
    top = env.max(axis=2)
    ax.imshow(top.T, origin="lower", extent=(grid.x[0], grid.x[-1], grid.y[0], grid.y[-1]), cmap="viridis",
              vmax=np.percentile(top, 99.5), aspect="equal")
    for t in targets:
        p = np.asarray(t.points_xyz)
        if t.kind == "line":
            ax.plot(p[:, 0], p[:, 1], "r-", lw=2)
        else:
            ax.plot(p[:, 0], p[:, 1], "r+", ms=10, mew=2)
    ax.set(title=title, xlabel="x (m)", ylabel="y (m)")


def describe(targets) -> list[str]:
    rows = []
    for t in targets:
        p = np.asarray(t.points_xyz)
        where = " - ".join(f"({q[0]:.2f}, {q[1]:.2f}, {q[2]:.2f})" for q in p)
        rows.append(f"| {t.kind} | {where} | {t.length_m:.2f} | {t.score:.2f} |")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(ROOT.parent / "shared/data/real/gpro_sns_100MHz_grid"))
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results"))
    ap.add_argument("--figures", default=str(ROOT / "docs/figures"))
    args = ap.parse_args(argv)
    files = sorted(Path(args.data).glob("XLINE*.DT1"))
    if len(files) < 2:
        ap.error(f"{args.data}: no XLINE*.DT1 lines")
    t_all = time.perf_counter()
    lines = [gpr3d.read(f).time_zero(method="peak").dewow().remove_background() for f in files]
    grid_survey = assemble_grid(lines, names=[f.name for f in files], line_spacing_m=0.2)
    eps, per_line = host_eps_r(files)
    print(f"eps_r {eps:.2f} (lines: {', '.join(f'{e:.1f}' for e in per_line)})", flush=True)
    cs = cscan(grid_survey, cell_m=0.05, window_s=8e-9, eps_r=eps)
    fig_dir = Path(args.figures)
    fig_dir.mkdir(parents=True, exist_ok=True)
    save_cscan_sheet(fig_dir / "real_grid_cscans.png", cs, dpi=70, title=f"{len(files)} lines, 100 MHz: C-scans "
                     f"(8 ns slices; depths for eps_r {eps:.1f})")
    depth = 4.0
    v = 299792458.0 / np.sqrt(eps)
    ring = 0.5 * v * (1.0 / 100e6)  # one period of the 100 MHz pulse after time zero: the direct wave rings there
    # the same settings as `gpr3d reconstruct grid.h5 --method pseudo3d|backprojection --eps-r ... --spacing 0.1
    # --max-depth 4 --min-depth ... --no-time-zero` (the lines were background-removed one by one above)
    same = dict(eps_r=eps, spacing_m=0.1, max_depth_m=depth, time_zero="none", remove_background=False,
                min_target_depth_m=ring)
    t = time.perf_counter()
    rec_p3 = reconstruct(grid_survey, ReconstructConfig(**same, method="pseudo3d"))
    t_p3 = time.perf_counter() - t
    p3, g, tg_p3 = rec_p3.envelope, rec_p3.grid, rec_p3.targets
    t = time.perf_counter()
    rec = reconstruct(grid_survey, ReconstructConfig(**same))
    t_3d = time.perf_counter() - t
    # every voxel migrated (--no-coarse-to-fine) beside the default's coarse-to-fine: time and targets
    t = time.perf_counter()
    every = reconstruct(grid_survey, ReconstructConfig(**same, coarse_to_fine=False))
    t_every = time.perf_counter() - t
    how = rec.refine or {}
    how = how.get("why") or how.get("skipped") or (f"every {how.get('stride')} columns first, then "
                                                  f"{100 * how.get('refined_fraction', 1.0):.0f} % of the voxels")
    same_targets = [(x.kind, np.round(x.points_xyz, 3).tolist()) for x in rec.targets] == \
        [(x.kind, np.round(x.points_xyz, 3).tolist()) for x in every.targets]
    plt = pyplot()
    for name, env, grid, tg, title in (("pseudo3d", p3, g, tg_p3, "pseudo-3D (2D Kirchhoff per line, interpolated)"),
                                       ("3d", rec.envelope, rec.grid, rec.targets, "3D back projection")):
        fig, ax = plt.subplots(2, 1, figsize=(11, 8.5))
        top_view(ax[0], env, grid, tg, f"{title}: maximum over depth, targets in red")
        front = env.max(axis=1)
        ax[1].imshow(front.T, origin="upper", extent=(grid.x[0], grid.x[-1], grid.depth[-1], grid.depth[0]),
                     cmap="viridis", vmax=np.percentile(front, 99.5), aspect="auto")
        ax[1].set(title="maximum over y", xlabel="x (m)", ylabel="depth (m)")
        save_figure(fig, fig_dir / f"real_grid_{name}.png", dpi=90)
    lines_md = [f"Host CPU: {cpu_name()}, {os.environ['NUMBA_NUM_THREADS']} threads; {len(files)} lines, "
                f"{grid_survey.n_traces} traces; eps_r {eps:.2f} (median of the lines' hybrid estimates, "
                f"{min(per_line):.1f}-{max(per_line):.1f}); grid 0.1 m to {depth} m; targets deeper than {ring:.2f} m "
                "(one period of the pulse below time zero, where the direct wave rings)", "",
                f"C-scans: {cs.values.shape[0]} slices of 8 ns on {cs.values.shape[1]} x {cs.values.shape[2]} cells "
                "of 0.05 m (`docs/figures/real_grid_cscans.png`)", "",
                f"pseudo-3D: {t_p3:.1f} s, {sum(x.kind == 'line' for x in tg_p3)} lines, "
                f"{sum(x.kind == 'point' for x in tg_p3)} points (`docs/figures/real_grid_pseudo3d.png`)", "",
                "| kind | where (x, y, depth m) | length m | score |", "|---|---|---|---|", *describe(tg_p3), "",
                f"3D back projection: {t_3d:.1f} s, {sum(x.kind == 'line' for x in rec.targets)} lines, "
                f"{sum(x.kind == 'point' for x in rec.targets)} points (`docs/figures/real_grid_3d.png`)", "",
                "| kind | where (x, y, depth m) | length m | score |", "|---|---|---|---|", *describe(rec.targets), "",
                f"coarse-to-fine (the default): {how}; migration {rec.timings_s['migrate']:.2f} s ({t_3d:.1f} s in "
                f"all) against {every.timings_s['migrate']:.2f} s ({t_every:.1f} s) with every voxel migrated "
                f"(--no-coarse-to-fine); the same targets to the millimetre: {'yes' if same_targets else 'no'}", "",
                f"total {time.perf_counter() - t_all:.0f} s"]
    write_table(args.out, "real_grid.md", "\n".join(lines_md), "real_grid.py", argv)


if __name__ == "__main__":
    main()
