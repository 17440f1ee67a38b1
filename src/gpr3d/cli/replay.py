"""``gpr3d replay``: feed a recording to live mode as a radar would, at a chosen rate."""

from __future__ import annotations

import math
from pathlib import Path

from gpr3d.cli._common import _in_range
from gpr3d.core.errors import GPR3DError

NAME = "replay"
HELP = "replay a recording as a radar delivers it (a TCP trace stream, or a DZT or DT1 file that grows)"
EPILOG = ("examples:\n  gpr3d replay survey.h5 --poses path.tum --to tcp://127.0.0.1:5600 --rate 800\n"
          "  gpr3d replay LINE.DZT --poses LINE.tum --to live/LINE.DZT --poses-out live/LINE.tum --speed 4\n"
          "  gpr3d replay run.h5 --imu imu.csv --odometry odometry.tum --to tcp://127.0.0.1:5600 --speed 1\n\n"
          "--rate: traces per second; --speed N: N times the recording's own rate (a DZT's scans per second).\n"
          "To tcp://: serves the first client that connects (gpr3d live tcp://HOST:PORT). With --imu (and\n"
          "--odometry, --wheel: the files 'gpr3d pose fuse' reads) the stream carries those records too, each\n"
          "message at its time among the traces' (the recording's trace times, on the IMU clock), for\n"
          "'gpr3d live --fuse'.")


def add_arguments(sp):
    sp.add_argument("input", help="the recording (any gpr3d reads; a DZT or DT1 for --to FILE.DZT/.DT1)")
    sp.add_argument("--poses", default=None, help="TUM trajectory, one pose per trace")
    sp.add_argument("--to", required=True, help="tcp://HOST:PORT (a server), or a .DZT or .DT1 file to grow (a DT1's "
                    "HD header copied beside it first)")
    sp.add_argument("--poses-out", default=None, help="with --to FILE: the TUM file the poses grow into")
    sp.add_argument("--rate", type=float, default=None, help="traces per second")
    sp.add_argument("--speed", type=float, default=None, help="times the recording's own trace rate")
    sp.add_argument("--loops", type=int, default=1, help="play the recording this many times (tcp only)")
    sp.add_argument("--loop-shift", type=float, default=0.0,
                    help="move each further pass this far along x (m): a long survey from a short one")
    sp.add_argument("--accept-timeout", type=float, default=60.0, help="seconds to wait for a client (tcp)")
    sp.add_argument("--imu", default=None, help="tcp: IMU samples to send beside the traces (CSV: t, ax, ay, az, gx, "
                                                "gy, gz)")
    sp.add_argument("--odometry", default=None, help="tcp, with --imu: camera poses to send (TUM, EuRoC or CSV)")
    sp.add_argument("--wheel", default=None, help="tcp, with --imu: survey wheel readings to send (CSV: t, distance)")


def _check_rate(args):
    if (args.rate is None) == (args.speed is None):
        raise GPR3DError("give --rate (traces per second) or --speed (times the recording's own rate)")
    _in_range(args.rate, "--rate", 1e-3, 1e7, "traces per second")
    _in_range(args.speed, "--speed", 1e-3, 1e5, "a factor")


def _rate(args, own_rate):
    if args.rate is not None:
        return args.rate
    if not own_rate:
        raise GPR3DError("--speed: the recording gives no trace rate; give --rate")
    return args.speed * own_rate


def _own_rate(survey):
    """A recording's own traces a second, from its timestamps (None without them)."""
    if survey.timestamps_s is None or survey.n_traces < 2:
        return None
    span = float(survey.timestamps_s[-1] - survey.timestamps_s[0])
    return (survey.n_traces - 1) / span if span > 0 else None


def run(args):
    from gpr3d.pipeline import attach_trajectory, read_recording, read_sensors, replay_to_file, replay_to_tcp

    _check_rate(args)
    if args.loops < 1:
        raise GPR3DError(f"--loops must be at least 1, got {args.loops}")
    if not math.isfinite(args.loop_shift):
        raise GPR3DError("--loop-shift must be a finite number of metres")
    _in_range(args.accept_timeout, "--accept-timeout", 0.1, 86400, "seconds")
    if (args.odometry or args.wheel) and not args.imu:
        raise GPR3DError("--odometry and --wheel go with --imu (a pose filter propagates with the IMU)")
    if args.imu and args.loops != 1:
        raise GPR3DError("--loops: a replay with sensor records (--imu) plays once")
    if args.imu and not args.to.startswith("tcp://"):
        raise GPR3DError("--imu, --odometry and --wheel are for --to tcp:// (a growing DZT carries traces only)")
    if args.to.startswith("tcp://"):
        if args.poses_out:
            raise GPR3DError("--poses-out is for --to FILE.DZT: a tcp:// stream carries each trace's pose")
        host, _, port = args.to[6:].rpartition(":")
        if not host or not port.isdigit() or not 0 <= int(port) < 65536:
            raise GPR3DError(f"--to {args.to}: expected tcp://HOST:PORT with a port in 0..65535")
        sensors = read_sensors(args.imu, args.odometry, args.wheel) if args.imu else None
        survey = read_recording(args.input)
        if args.poses:
            survey = attach_trajectory(survey, args.poses, source=str(args.input))
        rate = _rate(args, _own_rate(survey))
        n = replay_to_tcp(survey, int(port), host=host, rate=rate, loops=args.loops, loop_shift_m=args.loop_shift,
                          accept_s=args.accept_timeout, sensors=sensors,
                          on_listen=lambda p: print(f"serving {survey.n_traces * args.loops} traces on "
                                                    f"tcp://{host}:{p} at {rate:g} traces/s", flush=True),
                          log=print)
        print(f"sent {n} traces")
        return 0
    kind = Path(args.input).suffix.lower()
    if kind not in (".dzt", ".dt1") or Path(args.to).suffix.lower() != kind:
        raise GPR3DError("--to a file replays a DZT or DT1 recording into a file of its kind (.DZT, .DT1; or give "
                         "--to tcp://HOST:PORT)")
    if args.loops != 1 or args.loop_shift != 0:
        raise GPR3DError("--loops and --loop-shift are for tcp:// replays")
    if (args.poses is None) != (args.poses_out is None):
        raise GPR3DError("--to FILE.DZT takes --poses and --poses-out together (the poses grow beside the traces)")
    own = None
    if args.rate is None:  # (--speed: the recording's own rate; a DT1's from its traces' times, read with its HD)
        if kind == ".dzt":
            from gpr3d.io.dzt import read_dzt_header

            own = read_dzt_header(args.input)["scans_per_s"]
        else:
            own = _own_rate(read_recording(args.input))
    rate = _rate(args, own)
    n = replay_to_file(args.input, args.to, rate=rate, poses=args.poses, poses_out=args.poses_out)
    print(f"wrote {n} traces to {args.to} at {rate:g} traces/s")
    return 0
