"""Two revisions' back projection timed against each other in one run: for a change to the migration kernels.

A kernel's time moves by several per cent from one process to the next on the same host (where numba's arrays
land, the host's other load), as much as a small change gains; two tables made minutes apart cannot tell them
apart. This script times the base revision's kernels and the working tree's in alternating processes, round after
round, each side with its own numba cache, on the same survey, and prints both sides' spread.

The survey: ``bench_reconstruct.survey`` (``--traces`` traces along a cart's random path over 4 m x 4 m, the L-pipe
scene), on the grid ``reconstruct`` picks for it to 1.3 m (216 x 202 x 65 at 2 cm for 8000 traces). What is timed:
``BackProjection(..., aperture_deg=50, obliquity=True, spreading=True).adjoint(data, with_fold=True)``, the call
``reconstruct`` makes, in each process once after a first untimed call (numba's compile or cache load). The base
revision's ``src/`` is taken with ``git archive``; each side's first process compiles its kernels, the timed
rounds load them from its cache.

    python benchmarks/bench_kernel_ab.py --base REV [--rounds 8] [--traces 8000] [--threads 2]
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
import shutil  # noqa: E402
import subprocess  # noqa: E402
import tarfile  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GRID_FIELDS = ("x0", "y0", "d0", "dx", "dy", "dd", "nx", "ny", "nd")


def child(npz: str, image_out: str | None) -> None:
    """One timed adjoint with its fold on the problem in ``npz`` (whichever gpr3d is on the path); prints its
    seconds as JSON; with ``image_out`` saves the image and the fold there."""
    import gpr3d
    from gpr3d.core.grid import Grid3D
    from gpr3d.migration.operator import BackProjection

    want = Path(os.environ["PYTHONPATH"]).resolve()
    if want not in Path(gpr3d.__file__).resolve().parents:
        raise SystemExit(f"gpr3d was imported from {gpr3d.__file__}, not from {want}")
    p = np.load(npz)
    grid = Grid3D(**{k: (int(p[k]) if k.startswith("n") else float(p[k])) for k in GRID_FIELDS})
    op = BackProjection(grid, p["tx"], p["rx"], dt_s=float(p["dt_s"]), n_samples=int(p["data"].shape[1]),
                        t0_s=float(p["t0_s"]), eps_r=float(p["eps_r"]), aperture_deg=50, obliquity=True,
                        spreading=True)
    data = p["data"]
    op.adjoint(data, with_fold=True)  # compile, or load from the cache
    t = time.perf_counter()
    img, fold = op.adjoint(data, with_fold=True)
    s = time.perf_counter() - t
    if image_out:
        np.save(image_out, np.stack([img, fold]))
    print(json.dumps({"s": s}))


def _run_side(src: Path, cache: Path, npz: Path, image_out: Path | None, threads: int) -> float:
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache), "NUMBA_NUM_THREADS": str(threads),
           "GPR3D_WARMUP": "0"}
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(npz)]
    if image_out is not None:
        cmd += ["--image", str(image_out)]
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["no output"])[-1]
        raise SystemExit(f"bench_kernel_ab: the kernel of {src} did not run: {last}")
    return float(json.loads(r.stdout.strip().splitlines()[-1])["s"])


def _base_source(rev: str, into: Path) -> str:
    """``src/`` of git revision ``rev`` unpacked into ``into``; returns the commit's short hash."""
    r = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"bench_kernel_ab: --base {rev!r} is not a commit of this repository")
    commit = r.stdout.strip()
    into.mkdir(parents=True, exist_ok=True)
    tar = into / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(tar), commit, "src"], check=True)
    with tarfile.open(tar) as t:
        t.extractall(into, filter="data")
    return commit[:7]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", help="the git revision to time against the working tree (e.g. HEAD~1)")
    ap.add_argument("--rounds", type=int, default=8, help="processes per side, alternating (default 8)")
    ap.add_argument("--traces", type=int, default=8000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--image", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        return child(args.child, args.image)
    if not args.base:
        ap.error("--base REV is needed: the revision whose kernels the working tree's are timed against")
    if args.rounds < 1 or args.traces < 100 or args.threads < 1:
        ap.error("--rounds and --threads must be >= 1, --traces >= 100")
    try:
        Path(args.out).mkdir(parents=True, exist_ok=True)
    except OSError as e:
        ap.error(f"--out {args.out}: {e.strerror}")
    work = Path(tempfile.mkdtemp(prefix="gpr3d-kernel-ab-"))
    try:
        return _compare(args, argv, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _compare(args, argv, work: Path) -> int:
    base = _base_source(args.base, work / "base")

    from bench_reconstruct import survey
    from eval_reconstruction import EPS

    from gpr3d.migration.operator import antenna_positions
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct

    s = survey(args.traces)
    g = reconstruct(s, ReconstructConfig(eps_r=EPS, max_depth_m=1.3)).grid
    tx, rx = antenna_positions(s.positions_xyz, s.orientations_quat_wxyz, s.offset_m)
    npz = work / "problem.npz"
    np.savez(npz, data=s.data.astype(np.float32), tx=tx, rx=rx, dt_s=s.dt_s, t0_s=s.t0_s, eps_r=EPS,
             **{k: getattr(g, k) for k in GRID_FIELDS})
    sides = {f"base {base}": work / "base" / "src", "working tree": ROOT / "src"}
    times = {name: [] for name in sides}
    for i in range(args.rounds):
        for name, src in sides.items():
            img = work / f"{i}_{name.split()[0]}.npy" if i == 0 else None
            times[name].append(_run_side(src, work / f"cache_{name.split()[0]}", npz, img, args.threads))
            print(f"round {i + 1}: {name} {times[name][-1]:.3f} s", flush=True)
    a, b = (np.load(work / f"0_{n}.npy") for n in ("base", "working"))
    diff = [float(np.abs(a[i] - b[i]).max() / max(np.abs(a[i]).max(), 1e-30)) for i in range(2)]
    (tb, tw) = (np.array(times[n]) for n in sides)
    lines = [f"Host CPU: {cpu_name()}, {args.threads} threads; the adjoint with its fold (50 deg cone, obliquity and "
             f"spreading) of {args.traces} traces onto {g.nx} x {g.ny} x {g.nd} voxels, one timed call per process, "
             f"{args.rounds} processes per side, alternating", "",
             "| kernels | median s | min s | max s | rounds faster than the other side |", "|---|---|---|---|---|"]
    for name, t, other in ((f"base {base}", tb, tw), ("working tree", tw, tb)):
        lines.append(f"| {name} | {np.median(t):.3f} | {t.min():.3f} | {t.max():.3f} | {int((t < other).sum())} of "
                     f"{args.rounds} |")
    lines += ["", f"working tree / base, medians: {np.median(tw) / np.median(tb):.3f}; largest difference of the "
                  f"images {diff[0]:.1e} and of the folds {diff[1]:.1e} of their peaks"]
    write_table(args.out, "kernel_ab.md", "\n".join(lines), "bench_kernel_ab.py", argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
