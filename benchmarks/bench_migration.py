"""Migration speed: gpr3d's back-projection kernel against PyLops' Kirchhoff adjoint and plain numpy.

One problem for all: 500 traces (20 transmitter x 25 receiver positions scattered
over 2 m x 2 m, so every trace has its own tx-rx pair), 512 samples, a grid of
100 x 100 x 80 voxels, constant velocity (eps_r 6), no weights, no aperture.
The figure of merit is voxel-trace updates per second (500 x 800,000 = 4e8 per
migration). PyLops runs its ``Kirchhoff`` operator (analytic travel times, numba
engine, float32, a one-sample wavelet so no convolution is added); gpr3d runs its
explicit-SIMD adjoint and, for comparison, its plain numba kernel (what runs where the
SIMD kernel cannot be built, or with GPR3D_SIMD=0); numpy runs
gpr3d's reference engine on a 20-trace subset, scaled to a rate. The images of
gpr3d and PyLops are compared (correlation), to show they compute the same sum.

    python benchmarks/bench_migration.py [--threads 2] [--repeat 3]
    python benchmarks/bench_migration.py --big     # a 1e8-voxel reconstruction: wall time and peak memory
"""

from __future__ import annotations

import argparse
import os
import sys
import time

if __name__ == "__main__":  # numba and PyLops read the thread count at import
    for i, a in enumerate(sys.argv):
        if a == "--threads" and i + 1 < len(sys.argv):
            os.environ["NUMBA_NUM_THREADS"] = sys.argv[i + 1]
    os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import warnings

import numpy as np

from gpr3d.core.units import C0
from gpr3d.core.grid import Grid3D
from gpr3d.migration.operator import BackProjection

NS_SRC, NS_REC, NT, DT, EPS = 20, 25, 512, 0.1e-9, 6.0


def problem(seed=0):
    rng = np.random.default_rng(seed)
    src = np.c_[rng.uniform(0, 2, NS_SRC), rng.uniform(0, 2, NS_SRC), np.zeros(NS_SRC)]
    rec = np.c_[rng.uniform(0, 2, NS_REC), rng.uniform(0, 2, NS_REC), np.zeros(NS_REC)]
    tx = np.repeat(src, NS_REC, axis=0)
    rx = np.tile(rec, (NS_SRC, 1))
    grid = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 100, 100, 80)
    data = rng.standard_normal((NS_SRC * NS_REC, NT)).astype(np.float32)
    return src, rec, tx, rx, grid, data


def timed(fn, repeat):
    fn()  # compile / warm up
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return min(ts), float(np.median(ts)), out


def big(n_traces=16):
    """gpr3d reconstruct on a 500 x 500 x 400 grid (1e8 voxels): peak resident memory."""
    import resource

    from gpr3d.core.poses import quat_from_yaw
    from gpr3d.core.survey import Survey
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct

    rng = np.random.default_rng(0)
    pos = np.c_[rng.uniform(0, 9.98, n_traces), rng.uniform(0, 9.98, n_traces), np.zeros(n_traces)]
    pos[:2, :2] = [[0, 0], [9.98, 9.98]]
    s = Survey(data=rng.standard_normal((n_traces, NT)).astype(np.float32), dt_s=0.2e-9, positions_xyz=pos,
               orientations_quat_wxyz=quat_from_yaw(np.zeros(n_traces)), offset_m=0.1, eps_r=EPS)
    t = time.perf_counter()
    r = reconstruct(s, ReconstructConfig(spacing_m=0.02, pad_m=0.0, max_depth_m=8.0, time_zero="none"))
    wall = time.perf_counter() - t
    g = r.grid
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"reconstruct on {g.nx} x {g.ny} x {g.nd} = {g.size:.3g} voxels, {n_traces} traces: {wall:.1f} s, "
          f"peak resident memory {peak_gb:.2f} GB (limit 8 GB)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--big", action="store_true", help="only the 1e8-voxel memory check")
    args = ap.parse_args(argv)
    import numba

    if args.big:
        big()
        return

    src, rec, tx, rx, grid, data = problem()
    n_tr = len(tx)
    updates = n_tr * grid.size
    rows = []
    op = BackProjection(grid, tx, rx, dt_s=DT, n_samples=NT, eps_r=EPS)
    best, med, img_ours = timed(lambda: op.adjoint(data), args.repeat)
    rows.append(("gpr3d numba kernel (SIMD)", best, med, updates))
    op_scalar = BackProjection(grid, tx, rx, dt_s=DT, n_samples=NT, eps_r=EPS)
    op_scalar.simd = False
    best_s, med_s, img_scalar = timed(lambda: op_scalar.adjoint(data), args.repeat)
    rows.append(("gpr3d numba kernel (scalar)", best_s, med_s, updates))

    sub = slice(0, 20)
    op_np = BackProjection(grid, tx[sub], rx[sub], dt_s=DT, n_samples=NT, eps_r=EPS, engine="numpy")
    best_np, med_np, _ = timed(lambda: op_np.adjoint(data[sub]), 1)
    rows.append(("gpr3d numpy reference (20 traces)", best_np, med_np, 20 * grid.size))

    corr = None
    try:
        from pylops.waveeqprocessing import Kirchhoff

        t_axis = np.arange(NT) * DT
        v = C0 / np.sqrt(EPS)
        warnings.filterwarnings("ignore", category=FutureWarning, module="pylops")
        kop = Kirchhoff(grid.depth, grid.x, t_axis, src[:, [1, 0, 2]].T * np.array([[1], [1], [-1]]),
                        rec[:, [1, 0, 2]].T * np.array([[1], [1], [-1]]), v, np.array([1.0], dtype=np.float32), 0,
                        y=grid.y, mode="analytic", engine="numba", dtype="float32")
        d3 = data.reshape(NS_SRC, NS_REC, NT)
        best_k, med_k, img_k = timed(lambda: kop.H @ d3.ravel(), args.repeat)
        rows.append(("PyLops Kirchhoff adjoint (numba)", best_k, med_k, updates))
        # PyLops' model is (ny, nx, nz); ours (nx, ny, nd)
        img_k = np.asarray(img_k).reshape(grid.ny, grid.nx, grid.nd).transpose(1, 0, 2)
        corr = float(np.corrcoef(img_k.ravel(), img_ours.ravel())[0, 1])
    except ImportError:
        print("PyLops is not installed: pip install pylops")
    print(f"migration adjoint: {n_tr} traces x {NT} samples -> {grid.nx} x {grid.ny} x {grid.nd} voxels; "
          f"numba threads {numba.get_num_threads()}, {os.cpu_count()} CPUs")
    print(f"{'engine':<36} {'best s':>8} {'median s':>9} {'G updates/s':>12} {'vs PyLops':>10}")
    ref = next((r for r in rows if r[0].startswith("PyLops")), None)
    for name, best, med, n in rows:
        rate = n / best / 1e9
        ratio = f"{rate / (ref[3] / ref[1] / 1e9):.1f}x" if ref else "-"
        print(f"{name:<36} {best:8.3f} {med:9.3f} {rate:12.2f} {ratio:>10}")
    if corr is not None:
        print(f"image correlation gpr3d vs PyLops: {corr:.4f}")
    diff = float(np.abs(img_scalar - img_ours).max() / np.abs(img_scalar).max())
    print(f"largest difference SIMD vs scalar kernel: {diff:.1e} of the image's peak")


if __name__ == "__main__":
    main()
