"""Wall time of `gpr3d detect` on the 1040-trace GSSI recording, start-up included (median of N runs).

    python benchmarks/bench_detect.py [--repeat 5] [--threads 2]
"""

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DZT = ROOT.parent / "shared" / "data" / "real" / "gprpy_gssi_400MHz" / "FILE____032.DZT"


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args()
    src = DZT if DZT.exists() else ROOT / "src" / "gpr3d" / "data" / "FILE____032.DZT"
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "gpr3d", "detect", str(src), "--out", "/tmp/_bench_det.json"],
                           capture_output=True, text=True, env=env)
        times.append(time.perf_counter() - t)
        assert r.returncode == 0, r.stderr
    import numba.misc.numba_sysinfo as si

    cpu = si.get_sysinfo().get("CPU Name")
    print(f"| what | median s | min s | runs | host CPU |\n|---|---|---|---|---|\n"
          f"| gpr3d detect FILE____032.DZT (1040 traces, 8 windows), start-up included | "
          f"{statistics.median(times):.2f} | {min(times):.2f} | {args.repeat} | {cpu}, {args.threads} threads |")
    print(r.stdout.splitlines()[0])


if __name__ == "__main__":
    main()
