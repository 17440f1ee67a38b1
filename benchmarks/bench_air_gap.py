"""Antennas held above the ground (issue 13): where a buried sphere images with and without the air gap, and what
the refracted rays cost the back projection.

The survey: ``--traces`` antenna positions at random over a 0.6 m x 0.6 m patch, random headings, 6 cm tx-rx
offset, 1 GHz, eps_r 9, a sphere of 2 cm radius whose top lies 0.30 m deep; the data from gpr3d's forward model
with the antennas held ``gap`` above the ground (0, 5, 15, 30 and 50 cm). Each record is migrated twice onto a
1 cm grid: with ``air_gap_m = gap`` (each leg refracted at the surface, Newton on Fermat's time) and with no gap
(the antennas taken to sit on the ground). The table gives the envelope peak's depth and horizontal error for
both, and the adjoint's time for each (the refracted rays take the scalar depth loop, the ground-coupled ones
the SIMD loop).

    python benchmarks/bench_air_gap.py [--traces 1500]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

from gpr3d.core.grid import Grid3D  # noqa: E402
from gpr3d.migration.masking import image_envelope  # noqa: E402
from gpr3d.migration.operator import BackProjection, antenna_positions  # noqa: E402
from gpr3d.simulation.forward import ForwardScene, Sphere, forward_model  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--traces", type=int, default=1500)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(1)
    n = args.traces
    pos = np.c_[rng.uniform(0.2, 0.8, n), rng.uniform(0.2, 0.8, n), np.zeros(n)]
    yaw = rng.uniform(-3, 3, n)
    top, r = np.array([0.52, 0.47, 0.30]), 0.02
    scene = ForwardScene(eps_r=9.0, spheres=[Sphere((top[0], top[1], -top[2] - r), r)])
    dt, ns = 0.05e-9, 360
    grid = Grid3D(0.2, 0.2, 0.1, 0.01, 0.01, 0.005, 61, 61, 61)
    tx, rx = antenna_positions(pos, headings_rad=yaw, offset_m=0.06)
    rows = []
    for gap in (0.0, 0.05, 0.15, 0.30, 0.50):
        data = forward_model(scene, pos, headings_rad=yaw, offset_m=0.06, frequency_hz=1e9, n_samples=ns, dt_s=dt,
                             source_delay_s=0.0, air_gap_m=gap)
        row = [f"{gap:.2f}"]
        for g in (gap, 0.0):
            op = BackProjection(grid, tx, rx, dt_s=dt, n_samples=ns, eps_r=9.0, aperture_deg=50, obliquity=True,
                                air_gap_m=g)
            op.with_traces(slice(0, 2)).adjoint(data[:2])  # warm-up: loads the compiled kernels
            t = time.perf_counter()
            img = op.adjoint(data)
            sec = time.perf_counter() - t
            env = image_envelope(img)
            i, j, k = np.unravel_index(np.argmax(env), env.shape)
            err_d = grid.depth[k] - top[2]
            err_h = float(np.hypot(grid.x[i] - top[0], grid.y[j] - top[1]))
            row += [f"{100 * err_d:+.1f}", f"{100 * err_h:.1f}", f"{sec:.2f}"]
            if gap == 0.0:
                row += ["", "", ""]
                break
        rows.append(row)
    head = ("| air gap (m) | with the gap: depth error (cm) | horizontal (cm) | adjoint (s) | gap ignored: depth error "
            "(cm) | horizontal (cm) | adjoint (s) |")
    table = "\n".join([f"Host CPU: {cpu_name()}; {n} traces, grid 61 x 61 x 61, aperture 50 deg, eps_r 9, sphere top "
                       "0.30 m deep", "", head, "|" + "---|" * 7, *("| " + " | ".join(r) + " |" for r in rows)])
    write_table(args.out, "air_gap.md", table, "bench_air_gap.py", argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
