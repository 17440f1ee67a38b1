"""``gpr3d run``: the whole system on one recording (read, place, detect, depths, migrate, targets), resumable."""

from __future__ import annotations

from gpr3d.cli._common import (
    _eps_argument,
    _migration_engine,
    _out_folder,
    _reconstruct_defaults,
    add_detector_args,
)
from gpr3d.core.errors import GPR3DError

NAME = "run"
HELP = "the whole system on one recording: poses, detection, depths, 3D migration, targets and a report (resumable)"
EPILOG = ("examples:\n"
          "  gpr3d run gpr3d_demo/random_walk_survey.h5 --imu rig/imu.csv --odometry rig/odometry.tum \\\n"
          "      --wheel rig/wheel.csv --rig rig/rig.json --out site1\n"
          "  gpr3d run FILE____032.DZT --out line32                  (the file's survey-wheel positions)\n"
          "  gpr3d run LINE.DZT --trace-spacing 0.02 --eps-r 9 --out line   (no positions in the file)\n\n"
          "OUT: survey.h5, detections.json, reconstruction/ (volume, targets.json, figures), summary.json, run.json\n"
          "(the stages done); run the same line again to finish an interrupted run: finished stages are kept")


def add_arguments(sp):
    sp.add_argument("input", help="radar file (DZT, DT1/HD, RD3/RAD, SEG-Y, gprMax .h5/.out, gpr3d .h5)")
    sp.add_argument("--out", required=True, help="run folder")
    sp.add_argument("--channel", type=int, default=0, help="channel of a multi-channel file (default 0)")
    sp.add_argument("--format", default=None, help="force a reader: dzt, dt1, rd3, segy, gprmax, gpr3d")
    sp.add_argument("--poses", default=None, help="antenna poses, one per trace in trace order (TUM, EuRoC, CSV)")
    sp.add_argument("--imu", default=None, help="an IMU recording (CSV) fused with --odometry/--wheel/--rig; the "
                                                "poses reach the traces by their times")
    sp.add_argument("--odometry", default=None, help="camera poses (TUM) beside --imu")
    sp.add_argument("--wheel", default=None, help="survey-wheel distances (CSV: t,distance) beside --imu")
    sp.add_argument("--rig", default=None, help="rig file (JSON: imu_T_camera, imu_T_antenna) beside --imu")
    sp.add_argument("--track", default=None, help="a surveyed track the traces are placed on (x y z text, CSV, .DZG)")
    sp.add_argument("--trace-spacing", type=float, default=None, help="a straight line of this trace spacing (m), "
                                                                     "where the file has no positions")
    sp.add_argument("--eps-r", default=None, help="the host's relative permittivity, or 'file' (default: estimated "
                                                  "from the data, see --depth)")
    sp.add_argument("--depth", default="hybrid", choices=("hybrid", "net", "fit"),
                    help="how eps_r and the depths are estimated (default hybrid)")
    sp.add_argument("--depthnet", default=None, help="DepthNet weights (default: the shipped ones)")
    rc = _reconstruct_defaults()
    sp.add_argument("--spacing", type=float, default=rc.spacing_m,
                    help="voxel size (m; default: a tenth of the antenna's centre wavelength in the ground, 2 cm or "
                         "more; 2 cm where the file names no frequency)")
    sp.add_argument("--max-depth", type=float, default=rc.max_depth_m,
                    help="deepest voxel (m; default: what the time window reaches)")
    sp.add_argument("--signal-depth", action="store_true",
                    help="end the grid where the signal ends (neighbouring traces no longer alike)")
    add_detector_args(sp)


def run(args):
    from gpr3d.migration.reconstruct import ReconstructConfig, check_config
    from gpr3d.pipeline.run import RunConfig, run_pipeline

    eps = _eps_argument(args.eps_r)
    if args.signal_depth and args.max_depth is not None:
        raise GPR3DError("give --max-depth or --signal-depth, not both")
    settings = {"spacing_m": args.spacing, "max_depth_m": args.max_depth}
    if args.signal_depth:
        settings["signal_depth"] = True
    if args.device != "cpu":  # (the networks and the migration on the GPU)
        settings["engine"] = _migration_engine(None, args.device)
    check_config(ReconstructConfig(**settings), names={"spacing_m": "--spacing", "max_depth_m": "--max-depth"})
    _out_folder(args.out, "run")
    cfg = RunConfig(input=args.input, out=args.out, format=args.format, channel=args.channel, poses=args.poses,
                    imu=args.imu, odometry=args.odometry, wheel=args.wheel, rig=args.rig, track=args.track,
                    trace_spacing_m=args.trace_spacing, eps_r=eps, depth=args.depth, score=args.score,
                    weights=args.weights, depthnet=args.depthnet, device=args.device, runtime=args.runtime,
                    refiner=args.refiner, reconstruct=settings)
    from gpr3d.viz.worker import FigureWorker

    with FigureWorker() as figures:  # forked before any thread starts; draws the figures at the end
        summary = run_pipeline(cfg, log=print, figures=figures)
    from gpr3d.migration.targets import target_name

    print(f"{len(summary['targets'])} targets in {args.input}:")
    for i, t in enumerate(summary["targets"]):
        pts = "  ".join("(" + ", ".join(f"{v:.2f}" for v in p) + ")" for p in t["points_xyz"])
        print(f"  {t.get('name', target_name(i)):>4} {t['kind']:5s} depth {t['depth_m']:.2f} m  {pts}")
    print(f"wrote {args.out}/ (summary.json, reconstruction/targets.json)")
    return 0
