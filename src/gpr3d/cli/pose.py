"""``gpr3d pose``: antenna poses from an IMU, visual odometry and a survey wheel (error-state EKF)."""

from __future__ import annotations

from pathlib import Path

from gpr3d.cli._common import _in_range, _writable
from gpr3d.core.errors import GPR3DError

#: the longest rig simulation `pose simulate` runs (memory grows with it: 1e9 s once took 23 GB in 50 s)
MAX_SIMULATED_S = 3600.0


NAME = "pose"
HELP = "antenna poses from an IMU, visual odometry and a survey wheel (error-state EKF)"
EPILOG = ("examples:\n  gpr3d pose simulate --out rig1                 (a synthetic cart's recordings and truth)\n"
             "  gpr3d pose fuse --imu rig1/imu.csv --odometry rig1/odometry.tum --wheel rig1/wheel.csv \\\n"
             "      --rig rig1/rig.json --still 2 --out antenna.tum --truth rig1/truth.tum --figure paths.png\n"
             "  gpr3d pose fuse --bag run.bag --colour-topic /camera/color/image_raw \\\n"
             "      --depth-topic /camera/aligned_depth_to_color/image_raw --rig rig.json --out antenna.tum\n"
             "IMU CSV: t,ax,ay,az,gx,gy,gz (s, m/s^2, rad/s); wheel CSV: t,distance (s, m); odometry: a TUM file "
             "of camera poses\n(a jump in its frame times is lost tracking); rig JSON: imu_T_camera, imu_T_antenna "
             "(4 x 4), camera_time_offset_s.")


def add_arguments(sp):
    sp.add_argument("action", choices=("fuse", "simulate"), help="fuse recordings, or simulate a rig's recordings")
    sp.add_argument("--out", required=True, help="fuse: the antenna trajectory (TUM); simulate: a folder")
    sp.add_argument("--imu", default=None, help="IMU samples (CSV)")
    sp.add_argument("--bag", default=None,
                    help="fuse: a ROS 1 .bag or ROS 2 bag folder with the IMU and odometry (instead of --imu, "
                         "--odometry); simulate: also write the recordings as a ROS 2 bag (flag)",
                    nargs="?", const=True)
    sp.add_argument("--imu-topic", default=None, help="bag: the sensor_msgs/Imu topic (default: the only one)")
    sp.add_argument("--odometry-topic", default=None,
                    help="bag: camera poses (PoseStamped, PoseWithCovarianceStamped or Odometry; default: the only one)")
    sp.add_argument("--colour-topic", default=None, help="bag: colour images for RGB-D odometry (Open3D)")
    sp.add_argument("--depth-topic", default=None, help="bag: depth images (16UC1 mm or 32FC1 m) for RGB-D odometry")
    sp.add_argument("--camera-info-topic", default=None, help="bag: the depth camera's CameraInfo (default: the only one)")
    sp.add_argument("--keyframe", type=float, default=0.1,
                    help="RGB-D odometry: register frames to a keyframe renewed every this many metres (or 5 deg); "
                         "0: frame to frame (default 0.1)")
    sp.add_argument("--odometry", default=None, help="visual odometry: camera poses (TUM or CSV trajectory)")
    sp.add_argument("--odometry-sigma", default="0.03,0.01,0.0005",
                    help="odometry's error per frame: ROT_DEG,TRANS_FRAC,TRANS_FLOOR_M (default 0.03,0.01,0.0005)")
    sp.add_argument("--wheel", default=None, help="survey wheel: forward distance (CSV t,distance)")
    sp.add_argument("--rig", default=None, help="mounts and camera latency (JSON); default: all at the IMU, none")
    sp.add_argument("--still", type=float, default=1.0, help="seconds the cart stands still at the start (1)")
    sp.add_argument("--loops", action="store_true",
                    help="close loops where the cart revisits ground (RGB-D frames of a bag registered by Open3D)")
    sp.add_argument("--smooth", action="store_true",
                    help="fixed-interval smoothing after the filter (RTS): each pose also rests on later data")
    sp.add_argument("--estimate-offset", action="store_true",
                    help="estimate the camera-IMU time offset from the turns (gyro vs odometry) and use it")
    sp.add_argument("--flat-ground", type=float, default=None, metavar="SIGMA_M",
                    help="the ground is flat: hold the IMU at its start height within this (m)")
    sp.add_argument("--at", default=None, metavar="SURVEY",
                    help="fuse: write the poses at this recording's trace times, one per trace in trace order "
                         "(what reconstruct --poses takes)")
    sp.add_argument("--truth", default=None, help="a true antenna trajectory to report the APE against (evo)")
    sp.add_argument("--figure", default=None, help="PNG plan view of the path")
    sp.add_argument("--duration", type=float, default=90.0, help="simulate: seconds of motion (90)")
    sp.add_argument("--seed", type=int, default=0, help="simulate: seed")


def run(args):
    from gpr3d.io.trajectory import read_trajectory, write_tum
    from gpr3d.pipeline.poses import write_rig_recordings

    out = Path(args.out)
    if args.action == "simulate":
        from gpr3d.pose.rig import RigConfig, simulate_rig

        _in_range(args.duration, "--duration", 20, MAX_SIMULATED_S, "seconds of motion")
        run = simulate_rig(RigConfig(duration_s=args.duration, vo_gap=(args.duration / 2, 2.0)), seed=args.seed)
        from gpr3d.io.resultdir import result_folder

        _writable(out, "--out")
        wrote = "imu.csv, odometry.tum (camera poses), wheel.csv, truth.tum (antenna) and rig.json"
        with result_folder(out, command="pose simulate") as stage:
            write_rig_recordings(run, stage)
            if args.bag:
                from gpr3d.io.rosbag import write_bag

                write_bag(stage / "bag", imu=run.imu, trajectory=read_trajectory(stage / "odometry.tum"))
                wrote += ", bag/ (ROS 2: /imu, /odometry)"
        print(f"wrote {wrote} to {out}/: {run.path_length_m:.1f} m in {args.duration:g} s, odometry lost for 2 s at "
              f"{args.duration / 2:g} s ({len(read_trajectory(out / 'odometry.tum'))} odometry frames)")
        return 0
    if args.bag is True:
        raise GPR3DError("pose fuse --bag needs the bag's path")
    if args.bag and args.imu:
        raise GPR3DError("give --bag or --imu, not both")
    if not (args.imu or args.bag):
        raise GPR3DError("pose fuse needs --imu FILE.csv or --bag BAG")
    if args.bag and args.odometry:
        raise GPR3DError("with --bag, odometry comes from the bag (--odometry-topic, or --colour-topic and "
                         "--depth-topic); leave out --odometry")
    if not args.still > 0:
        raise GPR3DError(f"--still must be the positive number of seconds the cart stands at the start, got {args.still}")
    if args.flat_ground is not None and not args.flat_ground > 0:
        raise GPR3DError(f"--flat-ground must be a positive height tolerance in metres, got {args.flat_ground}")
    try:
        sig = [float(v) for v in args.odometry_sigma.split(",")]
    except ValueError:
        sig = []
    if len(sig) != 3 or min(sig) <= 0:
        raise GPR3DError(f"--odometry-sigma takes ROT_DEG,TRANS_FRAC,TRANS_FLOOR_M (three positive numbers), "
                         f"got {args.odometry_sigma!r}")
    if bool(args.colour_topic) != bool(args.depth_topic):
        raise GPR3DError("RGB-D odometry needs both --colour-topic and --depth-topic")
    if args.colour_topic and not args.bag:
        raise GPR3DError("--colour-topic and --depth-topic read a bag: give --bag")
    if not 0 <= args.keyframe <= 5:  # NaN fails too
        raise GPR3DError(f"--keyframe must be a distance in metres between 0 (frame to frame) and 5, got {args.keyframe}")
    if args.loops and not args.colour_topic:
        raise GPR3DError("--loops registers revisited RGB-D frames: give --bag with --colour-topic and --depth-topic")
    from gpr3d.pipeline.poses import fuse_recordings, poses_at_traces

    at = None
    if args.at:  # (read first: a recording without trace times is refused before the fusion)
        from gpr3d.pipeline.recording import read_recording

        at = read_recording(args.at)
        if at.timestamps_s is None:
            raise GPR3DError(f"--at {args.at}: its traces have no times to place the fused poses at")
    fused = fuse_recordings(imu=args.imu, bag=args.bag, odometry=args.odometry, wheel=args.wheel, rig=args.rig,
                            imu_topic=args.imu_topic, odometry_topic=args.odometry_topic,
                            colour_topic=args.colour_topic, depth_topic=args.depth_topic,
                            camera_info_topic=args.camera_info_topic, keyframe_m=args.keyframe, odometry_sigma=sig,
                            still_s=args.still, flat_ground_m=args.flat_ground, smooth=args.smooth,
                            estimate_offset=args.estimate_offset, loops=args.loops, log=print)
    res, source = fused.result, fused.source
    traj = res.antenna_trajectory()
    if at is not None:
        traj = poses_at_traces(traj, at, source=args.at)
    write_tum(traj, out)
    msg = (f"wrote {out}: {len(traj)} antenna poses{' (one per trace of ' + args.at + ')' if at is not None else ''}; odometry frames used {int(res.vo_used.sum())}, gated out "
           f"{int(res.vo_rejected.sum())}; zero-velocity updates {res.zupt_count}")
    if args.truth:
        from gpr3d.pose.metrics import ape

        a = ape(traj, read_trajectory(args.truth))
        msg += f"; APE against {Path(args.truth).name}: {a['rmse'] * 100:.1f} cm RMS over {a['n']} poses"
    if args.figure:
        from gpr3d.viz.maps import save_paths_png

        paths = {"fused": traj.positions_xyz}
        if args.truth:
            from gpr3d.pose.metrics import aligned_positions

            paths = {"truth": read_trajectory(args.truth).positions_xyz,
                     "fused (aligned)": aligned_positions(traj, read_trajectory(args.truth))}
        save_paths_png(args.figure, paths, title=f"antenna path: {Path(source).name}")
        msg += f"; figure {args.figure}"
    print(msg)
    return 0
