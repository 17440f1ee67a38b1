"""Read + process throughput (traces/s) on the 1040-trace GSSI file: gpr3d beside readgssi.

Both run the same chain in the same process, on the same file:
read -> dewow -> background removal (mean trace) -> zero-phase Butterworth band-pass
(100-800 MHz). readgssi's own functions are used for its side (readdzt, dewow,
bgr, bp). Each chain runs --repeat times; the table gives the median.

    python benchmarks/bench_read_process.py [--file PATH] [--repeat 7]

Needs readgssi (``pip install 'gpr3d[bench]'``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

import gpr3d
from gpr3d.core.deps import require

DEFAULT = Path(__file__).resolve().parents[1].parent / "shared/data/real/gprpy_gssi_400MHz/FILE____032.DZT"
FMIN, FMAX = 100e6, 800e6


def gpr3d_chain(path):
    t = [time.perf_counter()]
    s = gpr3d.read(path)
    t.append(time.perf_counter())
    s = s.dewow(window_s=1 / 400e6)
    t.append(time.perf_counter())
    s = s.remove_background()
    t.append(time.perf_counter())
    s = s.bandpass(fmin_hz=FMIN, fmax_hz=FMAX)
    t.append(time.perf_counter())
    return s.n_traces, np.diff(t)


def readgssi_chain(path):
    require("readgssi")
    from readgssi import dzt, filtering

    quiet = io.StringIO()
    t = [time.perf_counter()]
    with contextlib.redirect_stdout(quiet), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hdr, arrs, _ = dzt.readdzt(str(path))
        t.append(time.perf_counter())
        ar = arrs[0].astype(np.float64)
        ar = filtering.dewow(ar)
        t.append(time.perf_counter())
        ar = filtering.bgr(ar, hdr, win=0)
        t.append(time.perf_counter())
        ar = filtering.bp(ar, hdr, freqmin=FMIN / 1e6, freqmax=FMAX / 1e6)
        t.append(time.perf_counter())
    return ar.shape[1], np.diff(t)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--file", type=Path, default=DEFAULT if DEFAULT.exists() else None)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    if args.file is None:
        from gpr3d.data import example_dzt

        args.file = Path(str(example_dzt()))
    rows = {}
    for name, chain in (("gpr3d", gpr3d_chain), ("readgssi", readgssi_chain)):
        chain(args.file)  # warm-up (imports, caches)
        runs = [chain(args.file) for _ in range(args.repeat)]
        n = runs[0][0]
        stages = np.median(np.array([r[1] for r in runs]), axis=0)
        total = statistics.median(float(np.sum(r[1])) for r in runs)
        rows[name] = (n, stages, total)
    print(f"file: {args.file.name}   traces: {rows['gpr3d'][0]}   repeats: {args.repeat} (median)")
    print(f"{'reader':<10} {'read ms':>9} {'dewow ms':>9} {'bg ms':>8} {'bandpass ms':>12} {'total ms':>9} "
          f"{'traces/s':>10}")
    for name, (n, st, total) in rows.items():
        print(f"{name:<10} {st[0] * 1e3:9.2f} {st[1] * 1e3:9.2f} {st[2] * 1e3:8.2f} {st[3] * 1e3:12.2f} "
              f"{total * 1e3:9.2f} {n / total:10.0f}")
    ratio = rows["readgssi"][2] / rows["gpr3d"][2]
    print(f"speed-up gpr3d / readgssi (read + process): {ratio:.1f}x")


if __name__ == "__main__":
    main()
