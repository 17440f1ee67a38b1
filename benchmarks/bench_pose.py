"""Where the pose fusion's time goes (issue 32: poses are fused on the user's path, in ``gpr3d run`` and live
mode's ``--fuse``): the demo's cart rig (``gpr3d demo``'s settings: 200 s of IMU at 200 Hz, RGB-D odometry at
15 Hz, a survey wheel), simulated, fused by the error-state filter with its smoother, and its loops closed; and
one rotation's SO(3) exp and log, by gpr3d's own (``gpr3d.pose.imu``) and by SciPy's ``Rotation``, which the
filter calls at every IMU sample.

    python benchmarks/bench_pose.py [--repeat 3] [--seconds 200] [--out benchmarks/results/intel]

Best of ``--repeat`` for each row; the fused antennas' error against the truth at the survey's traces (mean and
largest, m) shows that a faster run gives the same poses.
"""

from __future__ import annotations

import argparse
import sys
import time
import timeit
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402


def fusion_rows(seconds: float, repeat: int) -> tuple[list, dict]:
    from dataclasses import replace

    from gpr3d.demo import DemoConfig, _survey_poses

    cfg = replace(DemoConfig(), walk_seconds=seconds)
    best, info = None, None
    for _ in range(repeat):
        t = time.perf_counter()
        _, _, inf = _survey_poses(cfg, lambda msg: None)
        whole = time.perf_counter() - t
        if best is None or whole < best[0]:
            best, info = (whole, inf["fuse_s"]), inf
    rows = [(f"the demo's rig, {seconds:g} s: simulated, fused, smoothed, loops closed", best[0]),
            ("of which fused, smoothed and loops closed", best[1])]
    return rows, info


def rotation_rows(repeat: int) -> list:
    import numpy as np
    from scipy.spatial.transform import Rotation

    from gpr3d.pose.imu import so3_exp, so3_log

    w = np.array([0.01, -0.02, 0.03])
    R = so3_exp(w)
    n = 20000

    def per_call(fn):
        return min(timeit.repeat(fn, number=n, repeat=repeat)) / n * 1e6

    return [("so3_exp of one vector, gpr3d (us)", per_call(lambda: so3_exp(w))),
            ("the same by SciPy's Rotation.from_rotvec(...).as_matrix() (us)",
             per_call(lambda: Rotation.from_rotvec(w).as_matrix())),
            ("so3_log of one matrix, gpr3d (us)", per_call(lambda: so3_log(R))),
            ("the same by SciPy's Rotation.from_matrix(...).as_rotvec() (us)",
             per_call(lambda: Rotation.from_matrix(R).as_rotvec()))]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=200.0, help="the rig's duration (the demo's: 200)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if args.repeat < 1:
        ap.error(f"--repeat must be 1 or more, got {args.repeat}")
    if not 10 <= args.seconds <= 3600:  # (also NaN)
        ap.error(f"--seconds must lie in 10..3600, got {args.seconds:g}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        ap.error(f"--out {out}: not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        ap.error(f"--out {out}: {exc.strerror}")
    fusion, info = fusion_rows(args.seconds, args.repeat)
    rot = rotation_rows(args.repeat)
    lines = [f"Host CPU: {cpu_name()}; best of {args.repeat}", "", "| what | seconds or microseconds |", "|---|---|"]
    lines += [f"| {name} | {v:.2f} s |" for name, v in fusion]
    lines += [f"| {name} | {v:.2f} |" for name, v in rot]
    lines += ["", f"Fused antennas against the truth at the traces: mean {info['antenna_error_mean_m'] * 100:.4f} cm, "
                  f"largest {info['antenna_error_max_m'] * 100:.4f} cm ({info['loop_closures']} loop closures, "
                  f"{info['vo_rejected']} odometry frames gated out)"]
    print("\n".join(lines))
    write_table(args.out, "bench_pose.md", "\n".join(lines), "bench_pose.py", argv)


if __name__ == "__main__":
    main()
