"""``gpr3d live``: migrate traces as they arrive and keep the targets current while the survey runs."""

from __future__ import annotations

from gpr3d.cli._common import _eps_argument, _in_range, _migration_engine, _out_folder, _reconstruct_defaults
from gpr3d.core.errors import GPR3DError

NAME = "live"
HELP = "live 3D: migrate traces as a radar delivers them, targets refreshed while surveying"
EPILOG = ("examples:\n  gpr3d live tcp://127.0.0.1:5600 --out site --eps-r 9\n"
          "  gpr3d live LINE.DZT --poses LINE.tum --out site --eps-r 6 --until-idle 10\n"
          "  gpr3d live LINE.DT1 --poses LINE.tum --out site --eps-r 6   # pulseEKKO; --dt NS where no HD yet\n"
          "  gpr3d live run.bag --dt 0.1 --trace-topic /gpr/traces --pose-topic /odometry --out site --eps-r 6\n"
          "  gpr3d live run.bag --dt 0.1 --fuse --rig rig.json --out site --eps-r 6   # poses fused as they come\n"
          "  gpr3d live tcp://127.0.0.1:5600 --fuse --rig rig.json --out site   # from the stream's IMU and odometry\n\n"
          "SOURCE: tcp://HOST:PORT (the trace stream of docs/CONVENTIONS.md: each trace with its pose, or with\n"
          "--fuse its IMU and odometry messages), a DZT\n"
          "or DT1 file the radar is writing with --poses, a TUM file written beside it, or a ROS bag (.bag, or a ROS 2\n"
          "bag folder) replayed at its own pace: a trace topic (a header and a float array named trace, samples\n"
          "or data), poses from a pose topic, --poses, or fused from its IMU and odometry topics (--fuse).\n"
          "Refreshed while running:\n"
          "OUT/live.json (traces, targets, detections); at the end: volume.h5, volume.vti, targets.json,\n"
          "config.json (a batch 'gpr3d reconstruct' with its settings gives the same volume), detections.json.\n"
          "The last line: N traces, R traces/s, lag L s (how long after the newest trace arrived the work\n"
          "on it ended).")


def add_arguments(sp):
    rc = _reconstruct_defaults()
    sp.add_argument("source", help="tcp://HOST:PORT, a growing DZT or DT1 file (with --poses), or a ROS bag")
    sp.add_argument("--out", required=True, help="output folder")
    sp.add_argument("--poses", default=None, help="TUM trajectory beside a growing file (one pose per trace), or for "
                                                  "a bag's traces (interpolated at their stamps)")
    sp.add_argument("--dt", type=float, default=None, help="sample interval in ns: a bag's (its messages carry none), "
                    "or a growing DT1's without its HD header")
    sp.add_argument("--trace-topic", default=None, help="a bag's GPR trace topic (default: the one such topic)")
    sp.add_argument("--pose-topic", default=None, help="a bag's pose topic (default: the one such topic)")
    sp.add_argument("--fuse", action="store_true",
                    help="the antenna's poses fused as they come (the filter of 'gpr3d pose fuse', no smoothing): "
                         "from a bag's IMU and odometry topics, or a tcp:// stream's IMU, camera pose and wheel "
                         "messages")
    sp.add_argument("--imu-topic", default=None, help="with --fuse: the bag's IMU topic (default: the one)")
    sp.add_argument("--odometry-topic", default=None,
                    help="with --fuse: the bag's odometry (camera pose) topic (default: the one)")
    sp.add_argument("--rig", default=None, help="with --fuse: the rig file (JSON: imu_T_camera, imu_T_antenna, "
                                                "camera_time_offset_s)")
    sp.add_argument("--still", type=float, default=None,
                    help="with --fuse: seconds the cart stands at the start (default 1)")
    sp.add_argument("--samples-per-trace", type=int, default=None,
                    help="a bag's messages hold several traces of this many samples (default: one a message)")
    sp.add_argument("--speed", type=float, default=1.0,
                    help="replay a bag at this many times its pace (default 1; 0: as fast as it reads)")
    sp.add_argument("--channel", type=int, default=0, help="channel of a multi-channel DZT (default 0)")
    sp.add_argument("--offset", type=float, default=None, help="transmitter-receiver offset of a growing file's "
                    "antenna (m; default: a DT1's HD header's separation, else 0)")
    sp.add_argument("--eps-r", default=None, help="relative permittivity (default: the stream's header)")
    sp.add_argument("--spacing", type=float, default=0.03, help="voxel size in metres (default 0.03)")
    sp.add_argument("--depth-spacing", type=float, default=0.02, help="voxel height in metres (default 0.02)")
    sp.add_argument("--max-depth", type=float, default=None, help="deepest voxel (m; default: the time window)")
    sp.add_argument("--aperture", type=float, default=rc.aperture_deg,
                    help=f"beam half-angle in degrees, in (0, 90) (default {rc.aperture_deg:g})")
    sp.add_argument("--aperture-radius", type=float, default=rc.aperture_m,
                    help="the aperture's horizontal radius (m): a trace adds only to the columns within it of its "
                         "antennas' midpoint, at any depth (0: none, the cone alone; default "
                         f"{'none' if rc.aperture_m is None else format(rc.aperture_m, 'g')})")
    sp.add_argument("--background-window", type=int, default=256,
                    help="traces in the moving background window (default 256), ending at each trace")
    sp.add_argument("--centred-background", action="store_true",
                    help="centre the background window on each trace (a trace then waits for half a window)")
    sp.add_argument("--refresh", type=float, default=0.4,
                    help="seconds between target refreshes (default 0.4; longer where one takes over a third of it)")
    sp.add_argument("--until-idle", type=float, default=5.0,
                    help="end once no trace has come for this many seconds after the first (default 5; 0: only at "
                         "the end mark)")
    sp.add_argument("--start-timeout", type=float, default=60.0,
                    help="give up when no trace at all has come in this many seconds (default 60; 0: wait)")
    sp.add_argument("--no-detect", action="store_true", help="no hyperbola detection on the windows")
    sp.add_argument("--weights", default=None, help="detector weights (default: the shipped model)")
    sp.add_argument("--runtime", default=None, choices=("auto", "torch", "onnx", "int8"),
                    help="the detector's runtime: int8 (default for the shipped model on the CPU: its 8-bit graph, "
                         "about 0.7x the float graph's time a window), onnx (the float graph), torch, or auto "
                         "(as gpr3d detect chooses; the default with --weights or a GPU)")
    sp.add_argument("--score", type=float, default=0.5, help="keep detections scoring at least this (0..1)")
    sp.add_argument("--detect-in-turn", action="store_true",
                    help="run the detector's windows in turn with the migration (default: in a thread of its own, "
                         "beside it)")
    sp.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:N")
    sp.add_argument("--refiner", default="auto", help="box refiner: auto (default: the shipped one with the shipped "
                    "detector, none with --weights), none, or a refiner's .pt/.onnx file")
    sp.add_argument("--connect-timeout", type=float, default=10.0,
                    help="seconds to keep trying to connect to a tcp:// source (default 10)")


def run(args):
    from gpr3d.migration.config import ReconstructConfig
    from gpr3d.migration.reconstruct import check_config
    from gpr3d.pipeline import LiveConfig, load_models, open_source, run_live

    _out_folder(args.out, "live")
    _in_range(args.refresh, "--refresh", 0.05, 3600, "seconds")
    _in_range(args.until_idle, "--until-idle", 0, 86400, "seconds")
    _in_range(args.start_timeout, "--start-timeout", 0, 86400 * 7, "seconds")
    _in_range(args.connect_timeout, "--connect-timeout", 0, 86400, "seconds")
    if args.offset is not None:
        _in_range(args.offset, "--offset", 0, 10, "metres")
    if not 0.0 <= args.score <= 1.0:
        raise GPR3DError(f"--score must lie in 0..1, got {args.score}")
    if not (0 < args.aperture < 90):
        raise GPR3DError(f"--aperture must lie in (0, 90) degrees for live mode, got {args.aperture:g}")
    if args.detect_in_turn and args.no_detect:
        raise GPR3DError("--detect-in-turn is for the detector: drop it or --no-detect")
    if args.runtime is not None and args.no_detect:
        raise GPR3DError("--runtime is for the detector: drop it or --no-detect")
    if args.background_window < 2:
        raise GPR3DError(f"--background-window must be at least 2 traces, got {args.background_window}")
    eps = _eps_argument(args.eps_r)
    if eps == "file":
        eps = None  # the stream's header is the file's
    rc = ReconstructConfig(eps_r=eps, spacing_m=args.spacing, depth_spacing_m=args.depth_spacing,
                           max_depth_m=args.max_depth, aperture_deg=args.aperture,
                           aperture_m=args.aperture_radius or None,
                           engine=_migration_engine(None, args.device), background_window=args.background_window,
                           background_trailing=not args.centred_background,
                           lattice=True)
    check_config(rc, names={"spacing_m": "--spacing", "depth_spacing_m": "--depth-spacing",
                            "max_depth_m": "--max-depth", "eps_r": "--eps-r", "aperture_m": "--aperture-radius"})
    detector = None
    if not args.no_detect:
        from gpr3d.detection.infer import fastest_engine

        runtime = args.runtime or fastest_engine(args.weights, args.device)
        detector, _ = load_models(detector=True, depth="none", weights=args.weights, device=args.device,
                                  runtime=runtime, refiner=args.refiner)
    cfg = LiveConfig(reconstruct=rc, background_window=args.background_window,
                     background_trailing=not args.centred_background, refresh_s=args.refresh,
                     detect=not args.no_detect, score=args.score, detect_thread=not args.detect_in_turn,
                     until_idle_s=None if args.until_idle == 0 else args.until_idle,
                     start_timeout_s=None if args.start_timeout == 0 else args.start_timeout)
    bag = {}
    if args.dt is not None:
        _in_range(args.dt, "--dt", 1e-4, 1e3, "ns")
        bag["dt_s"] = args.dt * 1e-9
    if args.speed != 1.0:
        _in_range(args.speed, "--speed", 0, 1e6, "times the bag's pace")
        bag["speed"] = None if args.speed == 0 else args.speed
    for name in ("trace_topic", "pose_topic", "samples_per_trace"):
        if getattr(args, name) is not None:
            bag[name] = getattr(args, name)
    fuse = {k: getattr(args, k) for k in ("imu_topic", "odometry_topic", "rig", "still")
            if getattr(args, k) is not None}
    if fuse and not args.fuse:
        raise GPR3DError(f"{', '.join('--' + k.replace('_', '-') for k in fuse)} are for --fuse (poses fused from "
                         "an IMU and odometry)")
    if args.fuse:
        still = fuse.pop("still", 1.0)
        _in_range(still, "--still", 0.05, 600, "seconds")
        fuse["still_s"] = still
    source = open_source(args.source, poses=args.poses, channel=args.channel, offset_m=args.offset,
                         connect_s=args.connect_timeout, bag=bag or None, fuse=fuse if args.fuse else None)
    summary = run_live(source, args.out, cfg, detector=detector, log=print)
    print(f"{summary.n_targets} targets, {summary.n_detections} detections; trace-to-target latency median "
          f"{summary.latency_s['median']:.2f} s, max {summary.latency_s['max']:.2f} s; at most {summary.peak_tiles} "
          f"tiles in memory; wrote {', '.join(summary.files)} to {args.out}/")
    print(summary.line())
    return 0
