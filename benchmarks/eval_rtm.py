"""Migration of gprMax B-scans compared (issue 11, item 5): reverse-time migration against Kirchhoff, Stolt and
back projection.

Data, all gprMax 4 (FDTD) B-scans, none made for or tuned on here:

* ``homogeneous``: the first ``--records`` B-scans of ``datasets/gprmax_survey.h5`` (survey-scale lines over
  concrete with rebar mats and conduits, and over soil with pipes, voids and tanks; 100-200 traces each);
* ``layered``: the three scenes of ``benchmarks/rtm_scenes.py`` (soil over wetter subsoil with pipes 25 cm apart, a
  slab on its base with a rebar mat at 12 cm spacing, a road with bars 10 cm apart at two depths), if built.

Every method images the same section on the same grid (RTM's cells: a tenth of the shortest wavelength), with the
true host velocity (layers where there are):

* ``back projection``: the diffraction stack, no weights, no aperture (gpr3d's ``BackProjection``, straight rays
  through the layers' average slowness);
* ``Kirchhoff``: the same with obliquity and spreading weights, a 50 deg aperture and the time derivative of the
  data (the Kirchhoff integral's far-field term);
* ``Stolt``: f-k migration at one velocity (for layers: the vertical average down to the deepest target);
* ``RTM``: ``gpr3d.migration.rtm.rtm_bscan`` (2D Maxwell TM FDTD, time-reversed injection, exploding reflector).

Every record: time zero at the Ricker source's peak (sqrt(2)/f), the mean trace removed. Per true target (from the
scene): the envelope's peak near it (within 10 cm, or half the distance to a neighbour at the same depth) ->
position error against the target's top; lateral width of that peak at half its height (resolution, cm and in
host wavelengths); its height against the section's largest (dB). Close pairs (same depth within 2 cm, <= 30 cm
apart): resolved if the envelope between the two peaks dips below 0.7 of the lower peak. Artefacts: the 95th
percentile of the envelope farther than one wavelength from every target (and below half a wavelength), against
the median target peak (dB; lower is cleaner). Seconds: the migration alone (numba compiled beforehand).

    python benchmarks/eval_rtm.py [--records 24] [--layered build/rtm_scenes] [--figure docs/figures/rtm_comparison.png]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import numpy as np  # noqa: E402
from scipy.signal import hilbert  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

from gpr3d.core.grid import Grid3D  # noqa: E402
from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.core.units import C0  # noqa: E402
from gpr3d.migration.operator import BackProjection, antenna_positions  # noqa: E402
from gpr3d.migration.rtm import rtm_bscan  # noqa: E402
from gpr3d.migration.traditional import stolt_migrate  # noqa: E402
from gpr3d.simulation.scene import Scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("back projection", "Kirchhoff", "Stolt", "RTM")


def records(n: int, layered_dir):
    """``(set, name, Survey, Scene)`` for the homogeneous gprMax survey records and the layered scenes."""
    from gpr3d.simulation.packed import PackedDataset

    ds = PackedDataset(ROOT / "datasets" / "gprmax_survey.h5")
    for i in range(min(n, len(ds))):
        s, _ = ds[i]
        yield "homogeneous", f"survey {int(ds.index[i])}", s, ds.scene(i)
    if layered_dir and Path(layered_dir).exists():
        for p in sorted(Path(layered_dir).glob("*.h5")):
            s = Survey.load(p)
            yield "layered", p.stem, s, Scene.from_dict(s.metadata["scene"])


def layers_of(scene: Scene):
    prof = scene.eps_profile()
    return prof if len(prof) > 1 else None


def average_eps(scene: Scene, depth: float) -> float:
    """The constant eps_r with the same vertical travel time down to ``depth``."""
    return (scene.vertical_time_s(depth) * C0 / depth) ** 2


def migrate_all(s: Survey, scene: Scene):
    """Each method's section ``(nx, nz)`` on RTM's grid, its seconds, and the grid axes."""
    f = scene.antenna.frequency_hz
    t0 = math.sqrt(2) / f
    data = (s.data - s.data.mean(axis=0, keepdims=True)).astype(np.float32)
    x = s.positions_xyz[:, 0]
    lay = layers_of(scene)
    eps = scene.medium.eps_r
    deepest = max(t.depth_m + 2 * t.radius_m for t in scene.targets)
    depth_m = min(scene.depth_m, deepest + 0.15)
    out, secs = {}, {}
    rtm_bscan(data[:, :64], x, s.dt_s, frequency_hz=f, depth_m=0.05, eps_r=eps, t0_s=0.0)  # compile
    r = rtm_bscan(data, x, s.dt_s, frequency_hz=f, depth_m=depth_m, eps_r=None if lay else eps, layers=lay, t0_s=t0)
    out["RTM"], secs["RTM"] = r.image, r.wall_s
    xs, zs, h = r.x_m, r.depth_m, r.cell_m
    grid = Grid3D(float(xs[0]), 0.0, float(zs[0]), h, 1.0, h, xs.size, 1, zs.size)
    pos = np.c_[x, np.zeros_like(x), np.zeros_like(x)]
    tx, rx = antenna_positions(pos, headings_rad=np.zeros(x.size), offset_m=s.offset_m)
    for name, kw, d in (("back projection", {}, data),
                        ("Kirchhoff", {"obliquity": True, "spreading": True, "aperture_deg": 50.0},
                         np.gradient(data, axis=1).astype(np.float32))):
        op = BackProjection(grid, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=t0,
                            eps_r=None if lay else eps, layers=lay, **kw)
        op.adjoint(d)  # warm-up: the kernels loaded before the timing
        t = time.perf_counter()
        out[name] = op.adjoint(d)[:, 0, :]
        secs[name] = time.perf_counter() - t
    eps_st = average_eps(scene, deepest) if lay else eps
    cut = int(round(t0 / s.dt_s))
    t = time.perf_counter()
    img, dz = stolt_migrate(data[:, cut:], float(np.median(np.diff(x))), s.dt_s, eps_st)
    # onto the common grid: linear in depth, then along x
    zst = dz * np.arange(img.shape[1])
    tmp = np.array([np.interp(zs, zst, row, right=0.0) for row in img])
    out["Stolt"] = np.array([np.interp(xs, x, tmp[:, k]) for k in range(zs.size)]).T.astype(np.float32)
    secs["Stolt"] = time.perf_counter() - t
    return out, secs, xs, zs


def score(img, xs, zs, scene: Scene):
    """Per-target rows and the section's artefact level (see the module's text)."""
    env = np.abs(hilbert(img, axis=1))
    top = float(env.max()) or 1.0
    lam = C0 / math.sqrt(scene.medium.eps_r) / scene.antenna.frequency_hz
    ts = sorted(scene.targets, key=lambda t: t.x_m)
    rows, peaks = [], []
    for t in ts:
        same = [abs(o.x_m - t.x_m) for o in ts if o is not t and abs(o.depth_m - t.depth_m) < 0.02]
        half = min([0.1] + [d / 2 for d in same])
        win_x = (xs >= t.x_m - half) & (xs <= t.x_m + half)
        win_z = (zs >= t.depth_m - lam / 2) & (zs <= t.depth_m + 2 * t.radius_m + lam / 2)
        if not win_x.any() or not win_z.any():
            rows.append(None)
            peaks.append(None)
            continue
        sub = env[np.ix_(win_x, win_z)]
        i, k = np.unravel_index(int(np.argmax(sub)), sub.shape)
        ix, kz = np.flatnonzero(win_x)[i], np.flatnonzero(win_z)[k]
        pk = float(env[ix, kz])
        line = env[:, kz] >= 0.5 * pk
        lo = ix
        while lo > 0 and line[lo - 1]:
            lo -= 1
        hi = ix
        while hi < xs.size - 1 and line[hi + 1]:
            hi += 1
        width = float(xs[hi] - xs[lo]) + (xs[1] - xs[0])
        rows.append({"err_m": math.hypot(xs[ix] - t.x_m, zs[kz] - t.depth_m), "width_m": width,
                     "width_lam": width / lam, "level_db": 20 * math.log10(pk / top)})
        peaks.append((ix, kz, pk))
    pairs = resolved = 0
    for a in range(len(ts)):
        for b in range(a + 1, len(ts)):
            ta, tb = ts[a], ts[b]
            if abs(ta.depth_m - tb.depth_m) > 0.02 or abs(ta.x_m - tb.x_m) > 0.3:
                continue
            if peaks[a] is None or peaks[b] is None:
                continue
            pairs += 1
            (ia, ka, pa), (ib, kb, pb) = peaks[a], peaks[b]
            n = abs(ib - ia) + 1
            ii = np.linspace(ia, ib, n).round().astype(int)
            kk = np.linspace(ka, kb, n).round().astype(int)
            resolved += float(env[ii, kk].min()) < 0.7 * min(pa, pb)
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    far = Z > lam / 2
    for t in ts:
        far &= np.hypot(X - t.x_m, Z - t.depth_m) > max(lam, 0.05)
    tp = [p[2] for p in peaks if p is not None]
    art = 20 * math.log10(float(np.percentile(env[far], 95)) / float(np.median(tp))) if far.any() and tp else math.nan
    return rows, pairs, resolved, art


def figure(path, shown):
    from gpr3d.viz._figures import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(len(shown), len(METHODS), figsize=(4 * len(METHODS), 2.9 * len(shown)), squeeze=False)
    for r, (name, out, xs, zs, scene) in enumerate(shown):
        for c, m in enumerate(METHODS):
            env = np.abs(hilbert(out[m], axis=1))
            ax = axes[r, c]
            ax.imshow(env.T / env.max(), extent=(xs[0], xs[-1], zs[-1], zs[0]), cmap="gray_r", aspect="auto",
                      vmin=0, vmax=1)
            for t in scene.targets:
                ax.add_patch(plt.Circle((t.x_m, t.depth_m + t.radius_m), t.radius_m, fill=False, color="r", lw=0.8))
            for lay in scene.layers:
                ax.axhline(lay.top_m, color="c", lw=0.6, ls="--")
            ax.set_title(f"{name}: {m}", fontsize=8)
            ax.tick_params(labelsize=7)
            if c == 0:
                ax.set_ylabel("depth (m)", fontsize=8)
            if r == len(shown) - 1:
                ax.set_xlabel("x (m)", fontsize=8)
    save_figure(fig, path, dpi=100)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--records", type=int, default=24, help="homogeneous gprMax survey records (default 24)")
    ap.add_argument("--layered", default=str(ROOT / "build" / "rtm_scenes"),
                    help="folder of rtm_scenes.py's layered B-scans (skipped if absent)")
    ap.add_argument("--figure", default=str(ROOT / "docs" / "figures" / "rtm_comparison.png"))
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if args.records < 0:
        ap.error("--records must be >= 0")
    stats = {}
    shown = []
    for kind, name, s, scene in records(args.records, args.layered):
        out, secs, xs, zs = migrate_all(s, scene)
        for m in METHODS:
            rows, pairs, res, art = score(out[m], xs, zs, scene)
            st = stats.setdefault((kind, m), {"err": [], "width": [], "wlam": [], "level": [], "pairs": 0,
                                              "resolved": 0, "art": [], "secs": 0.0, "records": 0, "missed": 0})
            ok = [r for r in rows if r is not None]
            st["err"] += [r["err_m"] for r in ok]
            st["width"] += [r["width_m"] for r in ok]
            st["wlam"] += [r["width_lam"] for r in ok]
            st["level"] += [r["level_db"] for r in ok]
            st["missed"] += len(rows) - len(ok)
            st["pairs"] += pairs
            st["resolved"] += res
            st["art"].append(art)
            st["secs"] += secs[m]
            st["records"] += 1
        print(f"{kind:12s} {name:28s} " + "  ".join(f"{m} {secs[m]:.2f} s" for m in METHODS), flush=True)
        if kind == "layered" or (kind == "homogeneous" and len(shown) == 0):
            shown.append((name, out, xs, zs, scene))
    if shown and args.figure:
        Path(args.figure).parent.mkdir(parents=True, exist_ok=True)
        figure(args.figure, shown)
    lines = [f"Host CPU: {cpu_name()}, {os.environ.get('NUMBA_NUM_THREADS')} threads. gprMax B-scans: "
             f"{stats.get(('homogeneous', 'RTM'), {}).get('records', 0)} homogeneous survey records, "
             f"{stats.get(('layered', 'RTM'), {}).get('records', 0)} layered scenes. Medians over targets "
             "(position: envelope peak to the target's top).", "",
             "| set | method | targets | position error (cm) | lateral width at half height (cm) | width / wavelength "
             "| peak vs section max (dB) | close pairs resolved | artefact level (dB, median) | seconds (all records) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for (kind, m), st in stats.items():
        n = len(st["err"])
        if not n:
            continue
        pr = f"{st['resolved']} / {st['pairs']}" if st["pairs"] else "-"
        lines.append(f"| {kind} | {m} | {n} | {100 * np.median(st['err']):.1f} | {100 * np.median(st['width']):.1f} | "
                     f"{np.median(st['wlam']):.2f} | {np.median(st['level']):.1f} | {pr} | "
                     f"{np.nanmedian(st['art']):.1f} | {st['secs']:.1f} |")
    if shown:
        lines += ["", f"Figure: `{os.path.relpath(args.figure, ROOT)}` (envelopes; red: true targets; cyan: layer tops)."]
    write_table(args.out, "rtm_comparison.md", "\n".join(lines), "eval_rtm.py", argv)


if __name__ == "__main__":
    main()
