"""Forward-model speed: A-scans per second (512 samples, 5 targets, random poses).

The scene is the issue's benchmark case: a pipe, a rebar, a diagonal pipe, a
sphere and a box in soil, antenna poses scattered at random over 4 m x 4 m with
random headings, direct waves and noise on. The kernel is compiled first; each
of --repeat runs simulates --n traces; the median is reported.

    NUMBA_NUM_THREADS=2 python benchmarks/bench_forward.py [--n 200000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from gpr3d.simulation.forward import Box, ForwardScene, Pipe, Sphere, forward_model


def bench_scene() -> ForwardScene:
    return ForwardScene(
        eps_r=9.0, conductivity_s_m=0.002,
        pipes=[Pipe((0.0, 1.0, -0.9), (4.0, 1.0, -0.9), 0.05),
               Pipe((2.0, 0.0, -0.5), (2.0, 4.0, -0.5), 0.008),
               Pipe((0.5, 0.5, -1.2), (3.5, 3.5, -1.2), 0.08, "dielectric", 1.0)],
        spheres=[Sphere((3.0, 3.0, -0.7), 0.15)],
        boxes=[Box((0.5, 3.0, -1.6), (1.5, 3.5, -1.3))],
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--samples", type=int, default=512)
    args = ap.parse_args(argv)
    import numba

    rng = np.random.default_rng(0)
    pos = np.c_[rng.uniform(0, 4, args.n), rng.uniform(0, 4, args.n), np.zeros(args.n)]
    yaw = rng.uniform(-np.pi, np.pi, args.n)
    scene = bench_scene()
    out = np.empty((args.n, args.samples), dtype=np.float32)
    kw = dict(offset_m=0.1, frequency_hz=500e6, n_samples=args.samples, time_window_s=60e-9,
              air_wave=1.0, ground_wave=0.5)
    forward_model(scene, pos[:100], headings_rad=yaw[:100], **kw)  # compile
    rows = []
    for label, extra in (("targets + direct waves", {}), ("+ noise", {"noise": 0.01})):
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            forward_model(scene, pos, headings_rad=yaw, out=out, **kw, **extra)
            times.append(time.perf_counter() - t)
        rows.append((label, args.n / statistics.median(times), args.n / min(times)))
    print(f"forward model: {args.n} A-scans x {args.samples} samples, 5 targets, "
          f"{numba.get_num_threads()} threads (NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'unset')}), "
          f"{os.cpu_count()} CPUs")
    print(f"{'case':<26} {'A-scans/s (median)':>20} {'A-scans/s (best)':>18} {'target':>10}")
    for label, med, best in rows:
        print(f"{label:<26} {med:20,.0f} {best:18,.0f} {20000:>10,}")


if __name__ == "__main__":
    main()
