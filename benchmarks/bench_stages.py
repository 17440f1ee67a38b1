"""Where a user's time goes (issue 32): every stage of ``gpr3d reconstruct``, ``gpr3d detect`` and (``--demo``)
``gpr3d demo``, run as a user runs them, first on a cold numba cache (a fresh clone) and then warm; and
``reconstruct`` beside a plain aperture-limited back projection of the same survey in the same run.

The survey: ``--traces`` raw A-scans (default 8000; 512 samples over 40 ns, 500 MHz) along a cart's random path
over 4 m x 4 m (``bench_reconstruct.cart_path``, a trace every 2 cm), forward-modelled over the L-pipe scene of
``eval_reconstruction.py`` (eps_r 9), written as ``survey.h5`` (no positions) and ``path.tum`` (one pose per
trace): ``gpr3d reconstruct survey.h5 --poses path.tum --eps-r 9 --out rec`` at every other default.
``detect`` runs on the embedded 1040-trace DZT (``gpr3d.data.example_dzt``). ``reconstruct --no-coarse-to-fine``
(every voxel migrated; coarse-to-fine, :mod:`gpr3d.migration.refine`, is the default) runs warm beside it, and so
do ``--aperture-radius 1`` (the reference's own 1 m radius about each trace's midpoint, within the 50 deg cone)
alone and with ``--no-coarse-to-fine``.

Each command runs in a process of its own with ``gpr3d --timings`` (:mod:`gpr3d.core.timing`): the stages are
the library's own (read, poses, prepare, grid, migrate, fold, envelope, targets, figures, writes, ...), numba's
compilations a row of their own (and the wait for the background warm-up's, :mod:`gpr3d.core.warmup`), start-up
the process's age when ``main`` starts, and "exit and the rest" the process's wall time (measured here) less all
of those. A cold run has an empty ``NUMBA_CACHE_DIR`` of its own (a fresh install), with the background warm-up
or without it (``GPR3D_WARMUP=0``); the warm runs use the cache a cold one left (best of ``--repeat``). A
warm-up still running after a command is waited for before the next one starts.

The reference (the issue's): a plain numba back projection written here in a few lines, 3 cm x 3 cm x 2 cm
voxels over the antenna positions (plus 10 cm) down to 1.3 m, every trace within 1 m (horizontally) of a column
summed at every depth of it, linear interpolation, no weights; its compile time apart, best of ``--repeat``.

    python benchmarks/bench_stages.py [--traces 8000] [--threads 2] [--repeat 2] [--demo]
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
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402

from bench_reconstruct import cart_path  # noqa: E402
from eval_reconstruction import EPS, F, NS, OFFSET, WINDOW, scene  # noqa: E402

from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.io.trajectory import write_tum  # noqa: E402
from gpr3d.migration.operator import antenna_positions  # noqa: E402
from gpr3d.simulation.forward import forward_model  # noqa: E402

C0 = 299792458.0


@numba.njit(parallel=True, fastmath=True)
def plain_aperture_bp(data, tx, rx, x, y, depth, t0, dt, slow, radius, out):
    """The reference: for each column, every trace whose tx-rx midpoint lies within ``radius`` (horizontally)
    summed at every depth; two-way time from tx to the voxel to rx, linear interpolation, no weights. ``data``
    is padded with two zero samples."""
    nx, ny, nd = out.shape
    ns = data.shape[1] - 2
    for ix in numba.prange(nx):
        for iy in range(ny):
            for j in range(data.shape[0]):
                mx = 0.5 * (tx[j, 0] + rx[j, 0]) - x[ix]
                my = 0.5 * (tx[j, 1] + rx[j, 1]) - y[iy]
                if mx * mx + my * my > radius * radius:
                    continue
                ax, ay = x[ix] - tx[j, 0], y[iy] - tx[j, 1]
                bx, by = x[ix] - rx[j, 0], y[iy] - rx[j, 1]
                for k in range(nd):
                    za, zb = depth[k] + tx[j, 2], depth[k] + rx[j, 2]
                    u = (t0 + (math.sqrt(ax * ax + ay * ay + za * za) + math.sqrt(bx * bx + by * by + zb * zb))
                         * slow) / dt
                    u = min(max(u, 0.0), ns)
                    i = int(u)
                    out[ix, iy, k] += data[j, i] + (u - i) * (data[j, i + 1] - data[j, i])


def reference(s: Survey, tx, rx, repeat: int):
    """The plain back projection of ``s`` (time zero at its first sample): (best seconds, compile seconds, shape)."""
    f = np.float32
    lo, hi = s.positions_xyz[:, :2].min(axis=0) - 0.1, s.positions_xyz[:, :2].max(axis=0) + 0.1
    x = np.arange(lo[0], hi[0] + 1e-9, 0.03, dtype=f)
    y = np.arange(lo[1], hi[1] + 1e-9, 0.03, dtype=f)
    depth = np.arange(0.0, 1.3 + 1e-9, 0.02, dtype=f)
    padded = np.zeros((s.n_traces, s.n_samples + 2), f)
    padded[:, : s.n_samples] = s.data

    def run():
        out = np.zeros((x.size, y.size, depth.size), f)
        plain_aperture_bp(padded, tx.astype(f), rx.astype(f), x, y, depth, f(0.0), f(s.dt_s),
                          f(math.sqrt(EPS) / C0), f(1.0), out)
        return out

    t = time.perf_counter()
    run()
    first = time.perf_counter() - t
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t)
    return best, max(first - best, 0.0), (x.size, y.size, depth.size)


def timed_command(args, folder: Path, env: dict, name: str) -> dict:
    """``gpr3d --timings`` ARGS in a process of its own: the stages and the process's wall time."""
    t_json = folder / f"{name}.timings.json"
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "gpr3d", "--timings", str(t_json), *map(str, args)], env=env,
                       capture_output=True, text=True, cwd=folder)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"{name}: gpr3d {' '.join(map(str, args))} failed:\n{r.stderr}")
    doc = json.loads(t_json.read_text())
    rows = {"start-up": doc["startup_s"] or 0.0, **doc["stages"]}
    rows["exit and the rest"] = max(wall - sum(rows.values()), 0.0)
    # a background warm-up the command started may still compile the other kernel groups: let it finish before
    # the next measurement (it would share the cores)
    check = "from gpr3d.core import warmup; print(warmup.running() or '')"
    while subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True).stdout.strip():
        time.sleep(0.5)
    return {"rows": rows, "wall_s": wall, "stdout": r.stdout}


def best_of(runs: list) -> dict:
    return min(runs, key=lambda r: r["wall_s"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--traces", type=int, default=8000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--demo", action="store_true", help="time `gpr3d demo` too, cold and warm (minutes each)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if args.traces < 100 or args.repeat < 1 or args.threads < 1:
        ap.error("--traces must be >= 100, --repeat and --threads >= 1")
    from gpr3d.data import example_dzt

    work = Path(tempfile.mkdtemp(prefix="gpr3d-bench-stages-"))
    t = time.perf_counter()
    traj = cart_path(args.traces)
    data = forward_model(scene(), traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F,
                         n_samples=NS, time_window_s=WINDOW, air_wave=1.0, ground_wave=0.5)
    s = Survey(data=data, dt_s=WINDOW / NS, offset_m=OFFSET, frequency_hz=F)
    s.save(work / "survey.h5")
    write_tum(traj, work / "path.tum")
    t_sim = time.perf_counter() - t
    env = {**os.environ, "NUMBA_CACHE_DIR": str(work / "numba_cache"), "NUMBA_NUM_THREADS": str(args.threads),
           "GPR3D_WARMUP": "1"}

    def fresh(name, warmup=True):  # a numba cache of its own, empty: a fresh install
        return {**env, "NUMBA_CACHE_DIR": str(work / f"numba_cache_{name}"), "GPR3D_WARMUP": "1" if warmup else "0"}

    rec = ["reconstruct", work / "survey.h5", "--poses", work / "path.tum", "--eps-r", str(EPS), "--out", work / "rec"]
    det = ["detect", example_dzt(), "--out", work / "d.json"]
    runs = {"reconstruct, cold cache, no warm-up": timed_command(rec, work, fresh("r0", False), "rec00")}
    runs["reconstruct, cold cache"] = timed_command(rec, work, env, "rec0")
    runs["reconstruct, warm"] = best_of([timed_command(rec, work, env, f"rec{i + 1}") for i in range(args.repeat)])
    every = rec[:-2] + ["--no-coarse-to-fine", "--out", work / "rec_every"]
    runs["reconstruct --no-coarse-to-fine, warm"] = best_of([timed_command(every, work, env, f"every{i + 1}")
                                                             for i in range(args.repeat)])
    # the reference's own aperture (1 m about each trace's midpoint) beside the cone, coarse-to-fine and not
    radius = rec[:-2] + ["--aperture-radius", "1", "--out", work / "rec_r1"]
    runs["reconstruct --aperture-radius 1, warm"] = best_of([timed_command(radius, work, env, f"r1_{i + 1}")
                                                             for i in range(args.repeat)])
    both = rec[:-2] + ["--aperture-radius", "1", "--no-coarse-to-fine", "--out", work / "rec_r1_every"]
    runs["reconstruct --aperture-radius 1 --no-coarse-to-fine, warm"] = best_of(
        [timed_command(both, work, env, f"r1every{i + 1}") for i in range(args.repeat)])
    runs["detect, cold cache"] = timed_command(det, work, fresh("d"), "det0")
    runs["detect, warm"] = best_of([timed_command(det, work, env, f"det{i + 1}") for i in range(args.repeat)])
    if args.demo:
        demo = ["demo", "--out", work / "demo"]
        runs["demo, cold cache, no warm-up"] = timed_command(demo, work, fresh("x0", False), "demo00")
        runs["demo, cold cache"] = timed_command(demo, work, fresh("x"), "demo0")
        runs["demo, warm"] = timed_command(demo, work, fresh("x"), "demo1")
    for name, r in runs.items():
        print(f"{name}: {r['wall_s']:.1f} s", flush=True)

    # the reference, in this process, on the same data with the same poses (time zero: the first sample)
    tx, rx = antenna_positions(traj.positions_xyz, traj.orientations_quat_wxyz, OFFSET)
    s_ref = Survey(data=data, dt_s=WINDOW / NS, positions_xyz=traj.positions_xyz,
                   orientations_quat_wxyz=traj.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F)
    w_ref, c_ref, shape_ref = reference(s_ref, tx, rx, args.repeat)
    print(f"reference: {w_ref:.1f} s (+ {c_ref:.1f} s compile), grid {shape_ref}", flush=True)

    cfg = json.loads((work / "rec" / "config.json").read_text())
    g = cfg["grid"]
    order = []
    for r in runs.values():
        order += [k for k in r["rows"] if k not in order]
    order = [k for k in order if k != "exit and the rest"] + ["exit and the rest"]
    names = list(runs)
    lines = [f"Host CPU: {cpu_name()}, {args.threads} threads; `gpr3d reconstruct` on {args.traces} raw traces x {NS} "
             f"samples of a random-motion survey (forward model {t_sim:.0f} s; poses from a TUM file, eps_r "
             f"{EPS:g} given, every other setting the default: grid {g['nx']} x {g['ny']} x {g['nd']} at "
             f"{g['dx'] * 100:.0f} cm); `gpr3d detect` on the embedded 1040-trace DZT; seconds per stage "
             f"(warm: best of {args.repeat})", "",
             "| stage | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for k in order:
        lines.append(f"| {k} | " + " | ".join(f"{r['rows'][k]:.2f}" if k in r["rows"] else "-"
                                               for r in runs.values()) + " |")
    lines.append("| **process wall time** | " + " | ".join(f"**{r['wall_s']:.2f}**" for r in runs.values()) + " |")
    warm = runs["reconstruct, warm"]["wall_s"]
    warm_every = runs["reconstruct --no-coarse-to-fine, warm"]["wall_s"]
    refine = cfg["refine"] or {}
    warm_r1 = runs["reconstruct --aperture-radius 1, warm"]["wall_s"]
    warm_r1e = runs["reconstruct --aperture-radius 1 --no-coarse-to-fine, warm"]["wall_s"]
    refine_r1 = json.loads((work / "rec_r1" / "config.json").read_text())["refine"] or {}
    cold = runs["reconstruct, cold cache"]["wall_s"]
    cold0 = runs["reconstruct, cold cache, no warm-up"]["wall_s"]
    lines += ["", "| reconstruct against the plain reference (same survey, same run) | seconds | x reference |",
              "|---|---|---|",
              f"| plain aperture-limited numba back projection, 3 x 3 x 2 cm to 1.3 m, 1 m aperture "
              f"({shape_ref[0]} x {shape_ref[1]} x {shape_ref[2]}; its compile {c_ref:.1f} s apart) | {w_ref:.2f} | "
              "1.00 |",
              f"| `gpr3d reconstruct` end to end, warm, the defaults ({g['nx']} x {g['ny']} x {g['nd']}; "
              f"coarse-to-fine: stride {refine.get('stride')}, {100 * refine.get('refined_fraction', 1.0):.0f} % of "
              f"the voxels refined) | {warm:.2f} | {warm / w_ref:.2f} |",
              f"| `gpr3d reconstruct --no-coarse-to-fine` end to end, warm (every voxel migrated) | {warm_every:.2f} | "
              f"{warm_every / w_ref:.2f} |",
              f"| `gpr3d reconstruct --aperture-radius 1` end to end, warm (the reference's 1 m radius within the "
              f"cone; stride {refine_r1.get('stride')}, {100 * refine_r1.get('refined_fraction', 1.0):.0f} % "
              f"refined) | {warm_r1:.2f} | {warm_r1 / w_ref:.2f} |",
              f"| `gpr3d reconstruct --aperture-radius 1 --no-coarse-to-fine` end to end, warm | {warm_r1e:.2f} | "
              f"{warm_r1e / w_ref:.2f} |",
              f"| `gpr3d reconstruct` end to end, cold cache (first run, background warm-up) | {cold:.2f} | "
              f"{cold / w_ref:.2f} |",
              f"| `gpr3d reconstruct` end to end, cold cache, no warm-up (GPR3D_WARMUP=0) | {cold0:.2f} | "
              f"{cold0 / w_ref:.2f} |"]
    if args.demo:
        d00, d0, d1 = (runs[f"demo, {k}"]["wall_s"] for k in ("cold cache, no warm-up", "cold cache", "warm"))
        lines += ["", f"First demo (cold numba cache) / warm demo: {d0:.1f} s / {d1:.1f} s = {d0 / d1:.2f} with the "
                      f"background warm-up; {d00:.1f} s / {d1:.1f} s = {d00 / d1:.2f} without it (GPR3D_WARMUP=0)"]
    write_table(args.out, "bench_stages.md", "\n".join(lines), "bench_stages.py", argv)


if __name__ == "__main__":
    main()
