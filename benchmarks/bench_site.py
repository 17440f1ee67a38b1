"""Site-scale migration on Dask (issue 11, item 2): time and memory against the number of traces, 1 vs 2 workers.

The site: 20 m x 20 m, pipes 0.3-1.0 m deep crossing it (eps_r 9), surveyed by a cart's smooth random walk with a
trace every 2 cm (``--traces``, default 200,000: 4 km of path), forward-modelled (512 samples, 40 ns, 500 MHz).
The first 10k, 50k and all the traces are migrated onto 2 cm voxels (down to 1.3 m, the grid over the traces
surveyed so far), 50 deg cone, obliquity and spreading, in tiles of ``--tile`` metres with the cone's halo:

* on a local Dask cluster of 1 worker x 2 numba threads and of 2 workers x 1 thread (this host has 2 cores);
* "identical": the largest difference from one migration of the whole grid in one process (0 = bit for bit;
  the 200k reference is skipped with ``--no-reference``);
* memory: the workers' resident memory, sampled every 50 ms: idle (after importing gpr3d, before the run) and
  its peak during the run (the largest worker's), and the most traces one tile held (its own plus the halo's).

    python benchmarks/bench_site.py [--traces 200000] [--tile 5] [--no-reference]
"""

from __future__ import annotations

import os
import sys

if __name__ == "__main__":  # numba reads the thread count at import
    os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.core.grid import Grid3D  # noqa: E402
from gpr3d.migration.operator import BackProjection, antenna_positions  # noqa: E402
from gpr3d.migration.sitetiles import migrate_site  # noqa: E402
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model  # noqa: E402
from gpr3d.simulation.paths import random_walk  # noqa: E402

EPS, F, NS, WINDOW, OFFSET = 9.0, 500e6, 512, 40e-9, 0.1


def site_scene() -> ForwardScene:
    """Pipes across a 20 m x 20 m site: two long mains, an L, a diagonal, a row of short laterals."""
    pipes = [Pipe((1.0, 4.0, -0.95), (19.0, 4.0, -0.95), 0.05), Pipe((15.0, 1.0, -0.75), (15.0, 19.0, -0.75), 0.04),
             Pipe((3.0, 9.0, -0.6), (11.0, 9.0, -0.6), 0.04), Pipe((11.0, 9.0, -0.6), (11.0, 17.0, -0.6), 0.04),
             Pipe((2.0, 18.0, -0.45), (9.0, 12.0, -0.45), 0.03)]
    pipes += [Pipe((x, 13.0, -0.32), (x, 15.5, -0.32), 0.01) for x in (16.5, 17.5, 18.5)]
    return ForwardScene(eps_r=EPS, conductivity_s_m=0.002, pipes=pipes)


def site_survey(n: int, seed: int = 0) -> Survey:
    traj = random_walk(n, area=((0.0, 20.0), (0.0, 20.0)), step_m=0.02, turn_rate=0.1, seed=seed)
    data = forward_model(site_scene(), traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=OFFSET,
                         frequency_hz=F, n_samples=NS, time_window_s=WINDOW, air_wave=1.0, ground_wave=0.5)
    s = Survey(data=data, dt_s=WINDOW / NS, positions_xyz=traj.positions_xyz,
               orientations_quat_wxyz=traj.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F, eps_r=EPS)
    return s.time_zero(method="peak", search_s=6e-9).remove_background()


def operator(s: Survey, n: int) -> BackProjection:
    pos = s.positions_xyz[:n]
    g = Grid3D.covering(pos, depth_m=1.3, spacing_m=0.02, pad_m=0.1, d0=0.1)
    tx, rx = antenna_positions(pos, s.orientations_quat_wxyz[:n], OFFSET)
    return BackProjection(g, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=s.t0_s, eps_r=EPS, aperture_deg=50,
                          obliquity=True, spreading=True)


class WorkerMemory:
    """Samples the resident memory of the cluster's worker processes every 50 ms while it runs (``with``)."""

    def __init__(self, client):
        import psutil

        self.procs = [psutil.Process(pid) for pid in client.run(os.getpid).values()]
        self.start = max(p.memory_info().rss for p in self.procs) / 2**20
        self.peak = self.start

    def __enter__(self):
        import threading

        self._stop = threading.Event()

        def poll():
            while not self._stop.wait(0.05):
                self.peak = max(self.peak, max(p.memory_info().rss for p in self.procs) / 2**20)

        self._thread = threading.Thread(target=poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--traces", type=int, default=200_000)
    ap.add_argument("--tile", type=float, default=5.0, help="tile side (m)")
    ap.add_argument("--no-reference", action="store_true", help="skip the one-process reference for the largest run")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if args.traces < 1000 or not args.tile > 0:
        ap.error("--traces must be >= 1000 and --tile > 0")
    import distributed

    t = time.perf_counter()
    s = site_survey(args.traces)
    t_sim = time.perf_counter() - t
    print(f"forward model: {s.n_traces} traces in {t_sim:.0f} s", flush=True)
    sizes = sorted({min(k, args.traces) for k in (10_000, 50_000, args.traces)})
    rows = []
    clusters = {}
    for workers, threads in ((1, 2), (2, 1)):
        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=":0", silence_logs=40)
        clusters[workers] = (cluster, distributed.Client(cluster), threads)
    try:
        for n in sizes:
            op = operator(s, n)
            data = s.data[:n]
            ref = None
            if n < args.traces or not args.no_reference:
                t = time.perf_counter()
                ref = op.adjoint(data, with_fold=True)
                t_ref = time.perf_counter() - t
                print(f"{n}: one process {t_ref:.1f} s", flush=True)
            for workers, (cluster, client, threads) in clusters.items():
                client.restart()  # fresh workers: each peak is this run's
                client.run(lambda: __import__("gpr3d.migration.sitetiles"))  # imports out of the timing
                with WorkerMemory(client) as mem:
                    res = migrate_site(op, data, tile_m=args.tile, client=client, threads=threads)
                diff = "not run" if ref is None else \
                    f"{max(float(np.abs(res.image - ref[0]).max()), float(np.abs(res.fold - ref[1]).max())):.1g}"
                g = op.grid
                rows.append((n, f"{g.nx} x {g.ny} x {g.nd}", g.size / 1e6, f"{workers} x {threads}", res.tiles,
                             res.wall_s, n / res.wall_s, max(res.traces_per_tile), mem.start, mem.peak, diff))
                print(rows[-1], flush=True)
    finally:
        for cluster, client, _ in clusters.values():
            client.close()
            cluster.close()
    lines = [f"Host CPU: {cpu_name()}, {os.cpu_count()} cores; site 20 m x 20 m, {s.n_traces} traces x {s.n_samples} "
             f"samples (forward model {t_sim:.0f} s); 2 cm voxels to 1.3 m, 50 deg cone; tiles of {args.tile:g} m "
             f"with a {op.reach_m:.2f} m halo", "",
             "| traces | grid | M voxels | workers x threads | tiles | seconds | traces/s | most traces in a tile "
             "| worker memory, idle (MB) | worker memory, peak (MB) | max difference from one process |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r[0]} | {r[1]} | {r[2]:.1f} | {r[3]} | {r[4]} | {r[5]:.1f} | {r[6]:.0f} | {r[7]} | "
                     f"{r[8]:.0f} | {r[9]:.0f} | {r[10]} |")
    by = {(r[0], r[3]): r[5] for r in rows}
    big, small = sizes[-1], sizes[0]
    lines += ["", "Growth (seconds per trace, largest over smallest run): " + ", ".join(
        f"{w}: {by[(big, w)] / big / (by[(small, w)] / small):.2f}" for w in ("1 x 2", "2 x 1")) + "; 1.00 is linear."]
    write_table(args.out, "bench_site.md", "\n".join(lines), "bench_site.py", argv)


if __name__ == "__main__":
    main()
