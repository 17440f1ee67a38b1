"""gpr3d simulate throughput on this machine: 1 local Dask worker against 2.

Builds the same --n standard gprMax scenes (seed --seed) twice into fresh folders,
with 1 and with 2 worker processes, and prints samples per hour and the speed-up.
Run it on an otherwise idle machine.

    python benchmarks/bench_simulate.py [--n 6] [--seed 99] [--work bench_sim]
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from gpr3d.simulation.dataset import SimulateConfig, build_dataset


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=6)
    ap.add_argument("--seed", type=int, default=99)
    ap.add_argument("--engine", default="gprmax")
    ap.add_argument("--work", type=Path, default=Path("bench_sim"))
    args = ap.parse_args(argv)
    rows = []
    for workers in (1, 2):
        out = args.work / f"w{workers}"
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        s = build_dataset(SimulateConfig(out=str(out), n=args.n, seed=args.seed, engine=args.engine,
                                         workers=workers), progress=False, log=lambda *_: None)
        wall = time.perf_counter() - t
        rows.append((workers, wall, args.n / wall * 3600, s["mean_sample_wall_s"]))
    print(f"gpr3d simulate --engine {args.engine}: {args.n} standard scenes (seed {args.seed}), "
          "wall time including cluster start")
    print(f"{'workers':>8} {'wall s':>8} {'samples/hour':>13} {'s/sample/worker':>16}")
    for w, wall, rate, per in rows:
        print(f"{w:>8} {wall:8.1f} {rate:13.0f} {per:16.1f}")
    print(f"speed-up of 2 workers over 1: {rows[0][1] / rows[1][1]:.2f}x")


if __name__ == "__main__":
    main()
