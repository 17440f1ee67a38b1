"""Wall time of `gpr3d detect` on the 1040-trace GSSI recording, start-up included (median of N runs).

    python benchmarks/bench_detect.py [--repeat 5] [--threads 2] [--runtimes onnx torch]

One row per runtime (``--runtime onnx``: ONNX Runtime, no PyTorch import; ``torch``:
PyTorch + torchvision) and depth setting (``--depth hybrid``, the default since issue 9:
DepthNet in ONNX Runtime and the hyperbola fit; ``none``: boxes only). Writes
``benchmarks/results/bench_detect.md``. The must-show of issue 8 is <= 3 s including start-up.
"""

import argparse
import json
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
    p.add_argument("--runtimes", nargs="+", default=["onnx", "torch"])
    p.add_argument("--depths", nargs="+", default=["hybrid", "none"])
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_detect.md"))
    args = p.parse_args()
    src = DZT if DZT.exists() else ROOT / "src" / "gpr3d" / "data" / "FILE____032.DZT"
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _report import cpu_name

    cpu = cpu_name()
    lines = ["| runtime | --depth | median s | min s | in-process s (windows + merge + apexes) | targets | runs | "
             "host CPU |", "|---|---|---|---|---|---|---|---|"]
    found = {}
    for rt, depth in [(r, d) for r in args.runtimes for d in args.depths]:
        times, inner = [], []
        for _ in range(args.repeat):
            t = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "gpr3d", "detect", str(src), "--out", "/tmp/_bench_det.json",
                                "--runtime", rt, "--depth", depth], capture_output=True, text=True, env=env)
            times.append(time.perf_counter() - t)
            if r.returncode != 0:
                sys.exit(f"gpr3d detect --runtime {rt} failed: {r.stderr.strip()}")
            d = json.loads(Path("/tmp/_bench_det.json").read_text())
            inner.append(d["wall_s"])
        found[rt, depth] = [(round(x["apex_trace"]), round(x["apex_time_s"] * 1e9, 2)) for x in d["targets"]]
        lines.append(f"| {rt} | {depth} | {statistics.median(times):.2f} | {min(times):.2f} | {statistics.median(inner):.2f} | "
                     f"{len(d['targets'])} | {args.repeat} | {cpu}, {args.threads} threads |")
    table = "\n".join(lines)
    print(table)
    if len(found) > 1:
        same = len({tuple(v) for v in found.values()}) == 1
        print(f"same apexes (trace, ns) from every runtime: {same}")
        table += f"\n\nsame apexes (trace, ns) from every runtime: {same}"
    Path(args.out).write_text(f"`gpr3d detect {src.name}` (1040 traces, 8 windows), start-up included\n\n{table}\n\n"
                              f"command: python benchmarks/bench_detect.py {' '.join(sys.argv[1:])}\n")


if __name__ == "__main__":
    main()
