"""The data-sized voxel (issue 32, item 2: "a grid that follows the data") on real recordings: ``gpr3d reconstruct``
at its default (a tenth of the antenna's centre wavelength in the host, never under 2 cm:
``gpr3d.migration.reconstruct.voxel_spacing_m``) beside the fixed 2 cm voxel it replaced (``--spacing 0.02``).

The recordings: the real 25-line 100 MHz grid (``../shared/data/real/gpro_sns_100MHz_grid``, put together with
``gpr3d grid --spacing 0.2``; the host's eps_r estimated as ``reconstruct`` does by default) and the 1040-trace
400 MHz GSSI dune profile (``gprpy_gssi_400MHz/FILE____032.DZT``, its header's eps_r). Each command runs as a user
runs it, in a process of its own (warm numba cache: one untimed run first); the table gives the grid, the
migration's and the command's seconds and the targets found.

    python benchmarks/bench_voxel_default.py [--data ../shared/data/real] [--threads 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, threads_from_argv, write_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def gpr3d(*args, env=None):
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "gpr3d", *map(str, args)], capture_output=True, text=True, env=env)
    if r.returncode:
        sys.exit(f"bench_voxel_default.py: gpr3d {' '.join(map(str, args))}: {r.stderr.strip()}")
    return time.perf_counter() - t


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=str(ROOT.parent / "shared" / "data" / "real"))
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    data = Path(args.data)
    if not (data / "gpro_sns_100MHz_grid").is_dir():
        sys.exit(f"bench_voxel_default.py: --data {data}: no gpro_sns_100MHz_grid folder there")
    env = {**os.environ, "NUMBA_NUM_THREADS": str(args.threads), "OMP_NUM_THREADS": str(args.threads)}
    work = Path(tempfile.mkdtemp(prefix="gpr3d-voxel-"))
    grid = work / "grid.h5"
    gpr3d("grid", *sorted((data / "gpro_sns_100MHz_grid").glob("XLINE*.DT1")), "--spacing", "0.2", "--out", grid,
          env=env)
    records = [("real 100 MHz grid, 25 lines, 5871 traces", grid),
               ("real 400 MHz GSSI profile, 1040 traces", data / "gprpy_gssi_400MHz" / "FILE____032.DZT")]
    gpr3d("reconstruct", records[1][1], "--out", work / "warm", env=env)  # numba's cache filled, untimed
    rows = []
    for what, src in records:
        for label, spacing in (("data-sized (default)", []), ("fixed 2 cm (--spacing 0.02)", ["--spacing", "0.02"])):
            out = work / f"{src.stem}_{len(spacing)}"
            wall = gpr3d("reconstruct", src, "--out", out, *spacing, env=env)
            cfg = json.loads((out / "config.json").read_text())
            g = cfg["grid"]
            targets = json.loads((out / "targets.json").read_text())["targets"]
            kinds = {}
            for t in targets:
                kinds[t["kind"]] = kinds.get(t["kind"], 0) + 1
            rows.append(f"| {what} | {label} | {g['dx'] * 100:.1f} cm | {g['nx']} x {g['ny']} x {g['nd']} | "
                        f"{cfg['timings_s']['migrate']:.2f} | {wall:.2f} | {len(targets)} "
                        f"({', '.join(f'{n} {k}' for k, n in sorted(kinds.items()))}) | "
                        f"{max((t['score'] for t in targets), default=0):.2f} |")
    table = (f"Host CPU: {cpu_name()}, {args.threads} threads; `gpr3d reconstruct` at its default voxel (a tenth of "
             "the antenna's centre wavelength in the host, never under 2 cm) and at the fixed 2 cm it replaced; "
             "warm numba cache\n\n"
             "| recording | voxel | size | grid | migration s | command s | targets | best score |\n"
             "|---|---|---|---|---|---|---|---|\n" + "\n".join(rows))
    write_table(args.out, "voxel_default.md", table, "bench_voxel_default.py", argv)
    return 0


if __name__ == "__main__":
    threads_from_argv()
    sys.exit(main())
