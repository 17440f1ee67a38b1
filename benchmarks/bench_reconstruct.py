"""3D reconstruction speed at survey scale (issue 11): gpr3d's back projection against a plain numba one.

The survey: ``--traces`` A-scans (default 8000, 512 samples, 40 ns, 500 MHz) along a cart's random path over a
4 m x 4 m patch (the synthetic rig steered to random waypoints, a trace every 2 cm of path), forward-modelled
over the L-pipe scene of ``eval_reconstruction.py``. The grid: the one ``gpr3d reconstruct`` sizes for the survey
(2 cm voxels over the antenna positions plus 10 cm, down to 1.3 m: 216 x 202 x 65 for the default survey), used by
every row. Aperture: a 50 deg cone (gpr3d's default), obliquity and spreading weights, eps_r 9.

Rows:

* ``plain numba``: a straightforward parallel back projection written here, independent of gpr3d's kernels
  (each column visits every trace, skips it where the column lies outside the trace's cone at the deepest
  voxel, and sums the deeper voxels inside it, one voxel at a time);
* gpr3d's adjoint: tiled (the cost follows the aperture: tiles of 8 x 8 columns visit only the traces whose
  cone reaches them) or untiled (``GPR3D_TILED=0``: every column visits every trace), each with the explicit
  SIMD depth loop or the scalar one (``GPR3D_SIMD=0``); the SIMD loop reads the trace with hardware gathers or
  with scalar loads (``GPR3D_GATHER=1`` / ``0``; by default gpr3d picks by the CPU, see ``_kernels.read_path``);
* ``gpr3d reconstruct``: end to end (time zero, background removal, migration, fold, targets), tiled and not;
* a second table at the depth ``reconstruct`` picks by itself (95 % of the record's vertical reach, 1.7 m here):
  there the oblique paths deep in the cone outrun the record, and gpr3d's depth loop stops where the record ends
  (``_kernels.end_depth``) while the plain one reads the zero padding.

Effective updates per second = traces x grid voxels / seconds (the figure the issue sets: >= 3 G/s), and the
speed-up over the plain kernel; every image is compared with the plain one (largest difference relative to its
peak).

* with ``--torch``: the PyTorch engine (``engine="torch"``, the GPU path), on the CPU and, where there is one,
  on a CUDA GPU (every trace against every voxel: no tiles).

    python benchmarks/bench_reconstruct.py [--traces 8000] [--threads 2] [--repeat 2] [--torch]
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, threads_from_argv, write_table  # noqa: E402

if __name__ == "__main__":  # numba reads the thread count at import
    threads_from_argv()

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402

from eval_reconstruction import EPS, scene, simulate  # noqa: E402

from gpr3d.migration._kernels import GATHER, read_path  # noqa: E402
from gpr3d.migration.operator import BackProjection, antenna_positions  # noqa: E402
from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct  # noqa: E402
from gpr3d.pose.rig import RigConfig, simulate_rig  # noqa: E402
from gpr3d.pose.sync import trajectory_triggers  # noqa: E402

C0 = 299792458.0


@numba.njit(parallel=True, fastmath=True)
def plain_back_projection(data, tx, rx, x, y, depth, t0, dt, slow, tan_ap, out):
    """Sum of ``w * data_j(t_j(voxel))`` over traces, linear interpolation, inside a cone of half-angle atan(tan_ap)
    seen from the tx-rx midpoint; weights: obliquity x spreading. ``data`` padded with two zero samples."""
    nx, ny, nd = out.shape
    ns = data.shape[1] - 2
    dmax = depth[nd - 1]
    for ix in numba.prange(nx):
        for iy in range(ny):
            for j in range(data.shape[0]):
                mx = 0.5 * (tx[j, 0] + rx[j, 0]) - x[ix]
                my = 0.5 * (tx[j, 1] + rx[j, 1]) - y[iy]
                h = math.sqrt(mx * mx + my * my)
                if h > dmax * tan_ap:
                    continue
                ax, ay = x[ix] - tx[j, 0], y[iy] - tx[j, 1]
                bx, by = x[ix] - rx[j, 0], y[iy] - rx[j, 1]
                for k in range(nd):
                    if h > depth[k] * tan_ap:
                        continue
                    za, zb = depth[k] + tx[j, 2], depth[k] + rx[j, 2]
                    ra = math.sqrt(ax * ax + ay * ay + za * za)
                    rb = math.sqrt(bx * bx + by * by + zb * zb)
                    u = (t0 + (ra + rb) * slow) / dt
                    if u < 0:
                        u = 0.0
                    if u > ns:
                        u = ns
                    i = int(u)
                    f = u - i
                    w = 0.25 * (za / ra + zb / rb) * (ra + rb)
                    out[ix, iy, k] += w * (data[j, i] + f * (data[j, i + 1] - data[j, i]))


def survey(n_traces: int, seed: int = 0):
    """A cart's random path over 4 m x 4 m, a trace every 2 cm, forward-modelled over the L-pipe scene."""
    return simulate(cart_path(n_traces, seed), scene())


def cart_path(n_traces: int, seed: int = 0):
    """The antenna's poses of ``n_traces`` traces, one every 2 cm of a cart's random path over 4 m x 4 m."""
    dur = 30.0
    while True:
        run = simulate_rig(RigConfig(duration_s=dur, area=((0.0, 4.0), (0.0, 4.0)), turn_rate_rad_s=1.0,
                                     stops=3), seed=seed)
        truth = run.truth_trajectory()
        trig = trajectory_triggers(truth, 0.02)
        if trig.size >= n_traces:
            break
        dur *= 1.5 * n_traces / max(trig.size, 1)
    return truth.at(trig[:n_traces])


def timed(fn, repeat):
    fn()  # compile / warm up
    best, out = math.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--traces", type=int, default=8000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument("--torch", action="store_true",
                    help="add the PyTorch engine's rows (the CPU here, and CUDA where there is a GPU)")
    args = ap.parse_args(argv)
    if args.traces < 100 or args.repeat < 1 or args.threads < 1:
        ap.error("--traces must be >= 100, --repeat and --threads >= 1")
    t = time.perf_counter()
    s = survey(args.traces)
    t_sim = time.perf_counter() - t
    cfg = ReconstructConfig(eps_r=EPS, max_depth_m=1.3)
    g = reconstruct(s, cfg).grid  # the grid reconstruct picks (and numba's compilation, out of the timings)
    tx, rx = antenna_positions(s.positions_xyz, s.orientations_quat_wxyz, s.offset_m)
    updates = s.n_traces * g.size
    tan_ap = math.tan(math.radians(50.0))
    f = np.float32
    padded = np.zeros((s.n_traces, s.n_samples + 2), f)
    padded[:, : s.n_samples] = s.data

    def plain(g=g):
        out = np.zeros(g.shape, f)
        plain_back_projection(padded, tx.astype(f), rx.astype(f), g.x.astype(f), g.y.astype(f), g.depth.astype(f),
                              f(s.t0_s), f(s.dt_s), f(math.sqrt(EPS) / C0), f(tan_ap), out)
        return out

    rows = []
    w_plain, ref = timed(plain, args.repeat)
    peak = float(np.abs(ref).max())
    rows.append(("plain numba (written here)", w_plain, 0.0))
    op = BackProjection(g, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=s.t0_s, eps_r=EPS, aperture_deg=50,
                        obliquity=True, spreading=True)
    variants = (("tiled, SIMD, hardware gathers", True, True, True), ("tiled, SIMD, scalar loads", True, True, False),
                ("tiled, scalar", True, False, None), ("untiled, SIMD (gpr3d's read for this CPU)", False, True, None),
                ("untiled, scalar", False, False, None))
    for name, tiled, simd, gather in variants:
        op.tiled, op.simd, op.gather = tiled, simd, gather
        w, img = timed(lambda: op.adjoint(s.data), args.repeat)
        rows.append((f"gpr3d adjoint, {name}", w, float(np.abs(img - ref).max()) / peak))
        print(rows[-1], flush=True)
    if args.torch:  # the GPU path: every trace against every voxel of the grid, in batches
        import torch

        for engine in ("torch",) + (("torch:cuda",) if torch.cuda.is_available() else ()):
            op_t = BackProjection(g, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=s.t0_s, eps_r=EPS,
                                  aperture_deg=50, obliquity=True, spreading=True, engine=engine)
            where = "the CPU" if engine == "torch" else torch.cuda.get_device_name()
            w, img = timed(lambda: op_t.adjoint(s.data), args.repeat)
            rows.append((f"gpr3d adjoint, PyTorch engine on {where} ({torch.get_num_threads()} threads)"
                         if engine == "torch" else f"gpr3d adjoint, PyTorch engine on {where}", w,
                         float(np.abs(img - ref).max()) / peak))
            print(rows[-1], flush=True)
    for tiled in (True, False):
        os.environ["GPR3D_TILED"] = "1" if tiled else "0"
        w, res = timed(lambda: reconstruct(s, cfg), args.repeat)
        rows.append((f"gpr3d reconstruct end to end, {'tiled' if tiled else 'untiled'} "
                     f"({res.grid.nx} x {res.grid.ny} x {res.grid.nd}, {len(res.targets)} targets)", w,
                     math.nan))
        print(rows[-1], flush=True)
    os.environ.pop("GPR3D_TILED", None)
    # reconstruct's own depth (95 % of the record's vertical reach, no --max-depth): deep in the cone the oblique
    # paths outrun the record, and gpr3d's depth loop stops there (the plain loop reads the zero padding)
    cfg_d = ReconstructConfig(eps_r=EPS)
    g_d = reconstruct(s, cfg_d).grid
    w_plain_d, _ = timed(lambda: plain(g_d), args.repeat)
    w_d, res_d = timed(lambda: reconstruct(s, cfg_d), args.repeat)
    print(w_plain_d, w_d, flush=True)
    lines = [f"Host CPU: {cpu_name()}, {numba.config.NUMBA_NUM_THREADS} threads; {s.n_traces} traces x {s.n_samples} "
             f"samples (forward model {t_sim:.0f} s), grid {g.nx} x {g.ny} x {g.nd} = {g.size / 1e6:.2f} M voxels at "
             f"2 cm, aperture 50 deg, obliquity and spreading; best of {args.repeat}; gpr3d reads traces with "
             f"{'hardware gathers' if read_path() == GATHER else 'scalar loads'} on this CPU", "",
             "| method | seconds | effective G updates/s | speed-up over plain | max difference / peak |",
             "|---|---|---|---|---|"]
    for name, w, diff in rows:
        d = "-" if math.isnan(diff) else f"{diff:.1e}"
        lines.append(f"| {name} | {w:.2f} | {updates / w / 1e9:.2f} | {w_plain / w:.1f}x | {d} |")
    lines += ["", f"At reconstruct's own depth ({g_d.nx} x {g_d.ny} x {g_d.nd} voxels, to {g_d.depth[-1]:.2f} m; "
              "no --max-depth):", "", "| method | seconds | effective G updates/s | speed-up over plain |",
              "|---|---|---|---|",
              f"| plain numba (written here) | {w_plain_d:.2f} | {s.n_traces * g_d.size / w_plain_d / 1e9:.2f} | 1.0x |",
              f"| gpr3d reconstruct end to end, tiled ({len(res_d.targets)} targets) | {w_d:.2f} | "
              f"{s.n_traces * g_d.size / w_d / 1e9:.2f} | {w_plain_d / w_d:.1f}x |"]
    write_table(args.out, "bench_reconstruct.md", "\n".join(lines), "bench_reconstruct.py", argv)


if __name__ == "__main__":
    main()
