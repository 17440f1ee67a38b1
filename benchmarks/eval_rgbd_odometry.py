"""Visual odometry measured on rendered RGB-D frames through Open3D, alone and fused with the IMU (issue 10).

The synthetic cart rig drives for ``--duration`` seconds; its D435i-like camera (320 x 240 by default, 15 Hz,
40 deg down, 0.65 m above a textured floor with boxes on it; depth noise 0.0025 z^2 m, millimetre steps) renders
every frame at its true pose (``gpr3d.pose.render``), Open3D's RGB-D odometry registers each frame to its
keyframe (``gpr3d.pose.vo.rgbd_odometry``, a new keyframe every 10 cm or 5 deg), and the error-state EKF fuses
those motions with the rig's IMU. Scenarios: ``textured`` (the whole floor textured), the same registered frame
to frame (``keyframe_m=0``), and ``plain patch`` (a 4 m x 4 m patch of plain floor
where the camera looks half-way through the run: the odometry must report the frames it cannot register, and
the IMU must carry the pose across).

Per scenario, means over ``--runs`` paths: frames, frames lost (by the reason odometry gives), the per-frame
motion error (from its keyframe) against the truth (rotation, translation), the NEES of those motions with the calibrated
covariance (6 when calibrated), APE of odometry alone (chained) and fused (evo, SE(3) alignment, % of the
path), and the seconds per frame to render and to register.

    python benchmarks/eval_rgbd_odometry.py [--runs 2] [--duration 60] [--width 320]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

from gpr3d.pose.eskf import fuse  # noqa: E402
from gpr3d.pose.imu import so3_log  # noqa: E402
from gpr3d.pose.metrics import ape  # noqa: E402
from gpr3d.pose.render import CameraIntrinsics, FloorScene, render_rgbd, rig_camera_poses  # noqa: E402
from gpr3d.pose.rig import RigConfig, simulate_rig  # noqa: E402
from gpr3d.pose.vo import OdometryConfig, rgbd_odometry  # noqa: E402


def plain_patch_ahead(run, t, size=4.0):
    """A square of plain floor centred where the camera looks at time ``t`` (0.8 m ahead of the IMU)."""
    g = run.truth(np.array([t]))
    c = g["p"][0] + g["R"][0] @ np.array([0.8, 0.0, 0.0])
    h = size / 2
    return [((c[0] - h, c[0] + h), (c[1] - h, c[1] + h))]


def one_run(seed, duration, width, plain, keyframe_m=0.1):
    run = simulate_rig(RigConfig(duration_s=duration), seed=seed)
    scene = FloorScene.random(seed=seed, plain=plain_patch_ahead(run, duration / 2) if plain else [])
    intr = CameraIntrinsics.d435i(width)
    tc = run.vo.t_s
    T = rig_camera_poses(run, tc + run.config.camera_time_offset_s)
    rng = np.random.default_rng(seed)
    t_render = [0.0]

    def frames():
        for k, t in enumerate(tc):
            t0 = time.perf_counter()
            c, d = render_rgbd(scene, intr, T[k], rng=rng)
            t_render[0] += time.perf_counter() - t0
            yield t, c, d

    vo, rep = rgbd_odometry(frames(), intr, OdometryConfig(keyframe_m=keyframe_m))
    errs, nees = [], []
    for k in np.nonzero(vo.valid)[0]:
        Tt = np.linalg.inv(T[vo.ref[k]]) @ T[k]  # camera k in its keyframe
        e = np.concatenate([so3_log(vo.R[k].T @ Tt[:3, :3]), Tt[:3, 3] - vo.p[k]])
        errs.append(e)
        nees.append(e @ np.linalg.solve(vo.cov[k], e))
    errs = np.array(errs)
    measured = dataclasses.replace(run, vo=vo)
    res = fuse(run.imu, vo, run.filter_config())
    fused = res.antenna_trajectory()
    vo_traj = measured.vo_trajectory()
    return {"path_m": run.path_length_m, "frames": rep["frames"], "keyframes": rep["keyframes"], "lost": rep["frames"] - 1 - rep["registered"],
            "lost_reasons": rep["lost"], "rot_deg": float(np.degrees(np.sqrt(np.mean(np.sum(errs[:, :3] ** 2, 1))))),
            "trans_mm": float(1e3 * np.sqrt(np.mean(np.sum(errs[:, 3:] ** 2, 1)))),
            "nees_mean": float(np.mean(nees)), "nees_median": float(np.median(nees)),
            "vo_ape_m": ape(vo_traj, run.truth_trajectory(vo_traj.timestamps_s))["rmse"],
            "fused_ape_m": ape(fused, run.truth_trajectory())["rmse"], "gated": int(res.vo_rejected.sum()),
            "render_s": t_render[0] / rep["frames"], "odometry_s": rep["s_per_frame"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--width", type=int, default=320, help="image width in pixels (D435i field of view)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    if args.runs < 1 or args.duration < 20 or not 64 <= args.width <= 1280:
        ap.error("--runs must be >= 1, --duration >= 20 and --width in [64, 1280]")
    lines = [f"Host CPU: {cpu_name()}; {args.runs} runs of {args.duration:g} s per scenario (means); camera "
             f"{args.width} x {round(args.width * 0.75)} at 15 Hz, IMU 200 Hz", "",
             "| scenario | path m | frames (keyframes) | lost (reasons) | motion error per frame: rot deg / trans mm | motion NEES "
             "mean / median | VO alone APE m (% path) | fused APE m (% path) | gated | render s/frame | odometry "
             "s/frame |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, plain, kf in (("textured", False, 0.1), ("textured, frame to frame", False, 0.0), ("plain patch", True, 0.1)):
        rows = [one_run(s, args.duration, args.width, plain, kf) for s in range(args.runs)]
        m = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "lost_reasons"}
        reasons = {}
        for r in rows:
            for k, v in r["lost_reasons"].items():
                reasons[k] = reasons.get(k, 0) + v / len(rows)
        why = ", ".join(f"{k}: {v:.0f}" for k, v in reasons.items()) or "-"
        lines.append(f"| {name} | {m['path_m']:.1f} | {m['frames']:.0f} ({m['keyframes']:.0f}) | {m['lost']:.0f} ({why}) | "
                     f"{m['rot_deg']:.3f} / {m['trans_mm']:.2f} | {m['nees_mean']:.1f} / {m['nees_median']:.1f} | "
                     f"{m['vo_ape_m']:.3f} ({100 * m['vo_ape_m'] / m['path_m']:.2f} %) | {m['fused_ape_m']:.3f} "
                     f"({100 * m['fused_ape_m'] / m['path_m']:.2f} %) | {m['gated']:.0f} | {m['render_s']:.3f} | "
                     f"{m['odometry_s']:.3f} |")
        print(lines[-1], flush=True)
    write_table(args.out, "rgbd_odometry.md", "\n".join(lines), "eval_rgbd_odometry.py", argv)


if __name__ == "__main__":
    main()
