"""The ``gpr3d`` command: a thin layer over the library API.

Every subcommand calls public functions only; user errors (bad files, bad
arguments, missing extras) print one line on stderr and exit with status 1.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from dataclasses import replace
from pathlib import Path

from gpr3d import __version__
from gpr3d.core.errors import GPR3DError

#: the longest rig simulation `pose simulate` runs (memory grows with it: 1e9 s once took 23 GB in 50 s)
MAX_SIMULATED_S = 3600.0

EXAMPLES = """\
examples:
  gpr3d demo                                   run the end-to-end demo on the embedded recording
  gpr3d info LINE01.DZT XLINE00.DT1 ten_col.rd3
  gpr3d show LINE01.DZT --out line01.png --axis depth --cmap hot
  gpr3d process LINE01.DZT --steps time_zero dewow remove_background gain_tpow:power=1.5 \\
        bandpass:fmin_hz=2e8:fmax_hz=8e8 --out line01.h5
  gpr3d convert LINE01.DZT line01.sgy          (.h5 gpr3d HDF5, .sgy/.segy SEG-Y, .png figure)
  gpr3d detect LINE01.DZT --out det.json --overlay det.png
  gpr3d reconstruct survey.h5 --mask detect --out rec
  gpr3d pose fuse --imu imu.csv --odometry cam.tum --wheel wheel.csv --rig rig.json --out antenna.tum
"""


def _print_survey_info(path, surveys, as_json: bool):
    rows = []
    for s in surveys:
        m = s.metadata
        row = {
            "file": str(path),
            "format": m.get("format"),
            "channel": m.get("channel", 0),
            "n_traces": s.n_traces,
            "n_samples": s.n_samples,
            "dt_s": s.dt_s,
            "range_s": s.time_window_s,
            "antenna": m.get("antenna"),
            "frequency_hz": s.frequency_hz,
            "offset_m": s.offset_m,
            "eps_r": s.eps_r,
            "date": m.get("created") or m.get("date"),
            "positions": m.get("positions_source"),
            "length_m": None if s.distances_m is None else float(s.distances_m[-1]),
            "history": [h["step"] for h in s.history],
            "header_timewindow_s": m.get("header_timewindow_s"),
        }
        rows.append(row)
    if as_json:
        return rows
    for r in rows:
        ch = f" channel {r['channel']}" if len(rows) > 1 else ""
        print(f"{r['file']}{ch}: {r['format']}")
        print(f"  traces x samples : {r['n_traces']} x {r['n_samples']}")
        print(f"  sample interval  : {r['dt_s'] * 1e9:.6g} ns   range: {r['range_s'] * 1e9:.6g} ns")
        if r["header_timewindow_s"] and abs(r["header_timewindow_s"] - r["range_s"]) > 1e-3 * r["range_s"]:
            print(f"  header window    : {r['header_timewindow_s'] * 1e9:.6g} ns (TIMEWINDOW field; the range above"
                  " follows the sampling frequency)")
        ant = r["antenna"] or "?"
        freq = f"{r['frequency_hz'] / 1e6:.6g} MHz" if r["frequency_hz"] else "unknown frequency"
        print(f"  antenna          : {ant} ({freq}), tx-rx offset {r['offset_m']:.4g} m")
        if r["eps_r"]:
            print(f"  eps_r (header)   : {r['eps_r']:.4g}")
        if r["date"]:
            print(f"  recorded         : {r['date']}")
        if r["positions"] and r["length_m"] is not None:
            print(f"  positions        : {r['positions']}; path length {r['length_m']:.4g} m")
        elif r["positions"]:  # (no positions: the source says why, e.g. a gprMax file that kept no geometry)
            print(f"  positions        : {r['positions']}")
        if r["history"]:
            print(f"  processing       : {', '.join(r['history'])}")
    return rows


def cmd_info(args):
    from gpr3d.io.registry import read_all

    out, failed = [], 0
    for path in args.files:
        try:
            surveys = read_all(path, format=args.format)
        except (GPR3DError, MemoryError) as exc:
            if len(args.files) == 1:
                raise
            print(f"gpr3d: error: {exc if isinstance(exc, GPR3DError) else f'{path}: out of memory'}", file=sys.stderr)
            failed += 1
            continue
        out.extend(_print_survey_info(path, surveys, args.json))
    if args.json:
        print(json.dumps(out, indent=2))
    return 1 if failed else 0


def _check_marks_args(args) -> None:
    """One line for a wrong --marks-every / --marks (before any file is read)."""
    every, marks = getattr(args, "marks_every", None), getattr(args, "marks", None)
    if marks is not None and every is None:
        raise GPR3DError("--marks needs --marks-every (the distance between two marks)")
    if every is not None and not (math.isfinite(every) and every > 0):
        raise GPR3DError(f"--marks-every must be a positive distance in metres, got {every:g}")
    if every is not None and getattr(args, "track", None):
        raise GPR3DError("give --track or --marks-every, not both (each places the traces)")
    if isinstance(marks, str):
        args.marks = _number_list(marks, "--marks", int)


def _with_marks(survey, args):
    if getattr(args, "marks_every", None) is not None:
        from gpr3d.core.gridsurvey import place_by_marks

        survey = place_by_marks(survey, args.marks_every, marks=getattr(args, "marks", None))
    return survey


def _with_track(survey, args):
    survey = _with_marks(survey, args)
    if getattr(args, "track", None):
        from gpr3d.io.trajectory import apply_track, read_track

        survey = apply_track(survey, read_track(args.track))
    return survey


def _read_channel(args):
    from gpr3d.io.registry import read

    return _with_track(read(args.input, format=args.format, channel=args.channel), args)


def _apply_steps(survey, specs):
    from gpr3d.processing.steps import parse_step

    for spec in specs or []:
        name, kwargs = parse_step(spec)
        survey = survey.apply(name, **kwargs)
    return survey


def cmd_show(args):
    from gpr3d.viz.bscan import check_plot_args, save_bscan_png

    _check_suffix(args.out, (".png",), "--out")
    for flag, kw in (("--cmap", {"cmap": args.cmap}), ("--clip", {"clip_percentile": args.clip})):
        try:
            check_plot_args(**kw)
        except GPR3DError as exc:
            raise GPR3DError(f"{flag}: {exc}") from None
    s = _apply_steps(_read_channel(args), args.steps)
    if args.ascan is not None or args.style == "wiggle":
        from gpr3d.viz._figures import plot_to_png
        from gpr3d.viz.bscan import plot_ascan, plot_wiggles

        if args.ascan is not None and not 0 <= args.ascan < s.n_traces:
            raise GPR3DError(f"--ascan must be a trace in 0..{s.n_traces - 1}, got {args.ascan}")
        name = Path(args.input).name
        if args.ascan is not None:
            plot_to_png(args.out, plot_ascan, s, args.ascan, figsize=(8, 3.5), title=f"{name}: trace {args.ascan}")
        else:
            plot_to_png(args.out, plot_wiggles, s, figsize=(8, 5), title=name)
        print(f"wrote {args.out}")
        return 0
    if args.axis == "depth" and args.eps_r is None and s.eps_r is None:
        raise GPR3DError("--axis depth needs --eps-r (the file gives no eps_r)")
    save_bscan_png(s, args.out, axis=args.axis, eps_r=args.eps_r, cmap=args.cmap, clip_percentile=args.clip,
                   envelope=args.envelope,
                   title=f"{Path(args.input).name}" + (f" ({', '.join(h['step'] for h in s.history)})" if s.history else ""))
    print(f"wrote {args.out}")
    return 0


def _write(survey, out: str):
    suffix = Path(out).suffix.lower()
    if suffix in (".h5", ".hdf5"):
        survey.save(out)
    elif suffix in (".sgy", ".segy"):
        from gpr3d.io.segy import write_segy

        write_segy(survey, out)
    elif suffix == ".png":
        from gpr3d.viz.bscan import save_bscan_png

        save_bscan_png(survey, out)
    else:
        raise GPR3DError(f"{out}: unknown output type {suffix!r} (use .h5, .sgy/.segy or .png)")


_SURVEY_OUT = (".h5", ".hdf5", ".sgy", ".segy", ".png")


def cmd_process(args):
    _check_suffix(args.out, _SURVEY_OUT, "--out")  # before the work
    s = _apply_steps(_read_channel(args), args.steps)
    _write(s, args.out)
    print(f"wrote {args.out}: {s}")
    return 0


def cmd_convert(args):
    _check_suffix(args.out, _SURVEY_OUT, "output")
    s = _read_channel(args)
    _write(s, args.out)
    print(f"wrote {args.out}: {s}")
    return 0


def _writable(path, what: str) -> None:
    """Refuse (before any work, leaving nothing behind) an output whose folder cannot be made or written: a trial
    folder is made and removed in the nearest folder that exists (permissions alone do not tell, e.g. for root)."""
    import tempfile

    target = Path(path).absolute()
    base = target if target.is_dir() else target.parent
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise GPR3DError(f"{what} {path}: {base} is a file, not a folder")
    try:
        Path(tempfile.mkdtemp(prefix=".gpr3d-write-test-", dir=base)).rmdir()
    except OSError as exc:
        raise GPR3DError(f"{what} {path}: cannot write in {base} ({exc.strerror or exc})") from None


def _out_folder(path, command) -> Path:
    """``--out`` of a command that writes a folder: refused (before any work) where it names a file or cannot be
    written."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise GPR3DError(f"--out {out} is a file; {command} writes a folder (give a new or existing folder)")
    _writable(out, "--out")
    return out


def _number_list(text, what, kind=float):
    if not text:
        return None
    try:
        return [kind(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise GPR3DError(f"{what} must be a comma-separated list of {'whole numbers' if kind is int else 'numbers'}, "
                         f"got {text!r}") from None


def cmd_grid(args):
    from gpr3d.core.gridsurvey import assemble_grid, read_layout
    from gpr3d.io.registry import read

    _check_suffix(args.out, (".h5", ".hdf5"), "--out")
    if (args.spacing is None) == (args.layout is None):
        raise GPR3DError("give --spacing (parallel lines) or --layout (a file of line ends), one of them")
    if args.spacing is not None and not (args.spacing > 0 and args.spacing < 1e4):
        raise GPR3DError(f"--spacing must be a positive distance in metres, got {args.spacing:g}")
    if args.cross and args.layout is not None:
        raise GPR3DError("--cross goes with --spacing (a layout file places every line itself)")
    layout = read_layout(args.layout) if args.layout else None
    reversed_lines = _number_list(args.reversed, "--reversed", int)
    offsets = _number_list(args.start_offsets, "--start-offsets")
    cross = list(args.cross or [])
    for flag, v in (("--cross-spacing", args.cross_spacing), ("--cross-origin", args.cross_origin)):
        if v is not None and (not math.isfinite(v) or (flag == "--cross-spacing" and not v > 0)):
            raise GPR3DError(f"{flag} must be a {'positive' if flag == '--cross-spacing' else 'finite'} distance in "
                             f"metres, got {v:g}")
    files = list(args.lines) + cross
    surveys = [_apply_steps(_with_marks(read(f), args), args.steps) for f in files]
    g = assemble_grid(surveys, names=[Path(f).name for f in files], line_spacing_m=args.spacing,
                      direction=args.direction, start_offsets_m=offsets, serpentine=args.serpentine,
                      reversed_lines=reversed_lines, layout=layout, cross_lines=len(cross),
                      cross_spacing_m=args.cross_spacing, cross_origin_m=args.cross_origin or 0.0)
    g.save(args.out)
    lo, hi = g.positions_xyz[:, :2].min(axis=0), g.positions_xyz[:, :2].max(axis=0)
    sets = f"{len(args.lines)} + {len(cross)} perpendicular lines" if cross else f"{len(surveys)} lines"
    print(f"wrote {args.out}: {sets}, {g.n_traces} traces over x {lo[0]:.2f}..{hi[0]:.2f} m, "
          f"y {lo[1]:.2f}..{hi[1]:.2f} m")
    return 0


def cmd_cscan(args):
    from gpr3d.io.volume import write_cscan
    from gpr3d.processing.cscan import cscan
    from gpr3d.viz.maps import save_cscan_sheet

    if not (args.cell > 0 and args.cell < 1e3):
        raise GPR3DError(f"--cell must be a positive size in metres, got {args.cell:g}")
    if not args.window_ns > 0:
        raise GPR3DError(f"--window-ns must be positive, got {args.window_ns:g}")
    if args.fill is not None:  # (its smoothing kernel grows with it: 1e9 m once asked for 596 GiB)
        _in_range(args.fill, "--fill", 0.0, 20 * args.cell, f"a distance in metres, 0 to 20 cells of --cell {args.cell:g}")
    eps = _eps_argument(args.eps_r)
    out = _out_folder(args.out, "cscan")
    s = _apply_steps(_read_channel(args), args.steps)
    eps_r = s.eps_r if eps == "file" else eps
    cs = cscan(s, cell_m=args.cell, window_s=args.window_ns * 1e-9, eps_r=eps_r, fill_m=args.fill)
    from gpr3d.io.resultdir import result_folder

    with result_folder(out, command="cscan") as stage:  # the whole result, or the previous one: never a mix
        write_cscan(stage / "cscan.h5", cs)
        save_cscan_sheet(stage / "cscan.png", cs,
                         title=f"{Path(args.input).name}: C-scans ({args.window_ns:g} ns slices)")
    print(f"wrote {out}/cscan.h5 and cscan.png: {cs.values.shape[0]} slices of {cs.values.shape[1]} x "
          f"{cs.values.shape[2]} cells of {args.cell:g} m")
    return 0


def cmd_migrate(args):
    from gpr3d.io.volume import write_profile
    from gpr3d.migration.profile import migrate_profile
    from gpr3d.viz.bscan import save_profile_png

    if (args.eps_r is None) == (args.velocity is None):
        raise GPR3DError("give --eps-r or --velocity (one of them)")
    if args.velocity is not None and not 0.001 <= args.velocity <= 0.2998:
        raise GPR3DError(f"--velocity must be a wave speed in m/ns, between 0.001 and c = 0.2998, got {args.velocity:g}")
    for flag, value in (("--max-depth", args.max_depth), ("--spacing", args.spacing),
                        ("--trace-spacing", args.trace_spacing)):
        if value is not None and not value > 0:
            raise GPR3DError(f"{flag} must be positive, got {value:g}")
    if not (math.isfinite(args.air_gap) and args.air_gap >= 0):
        raise GPR3DError(f"--air-gap must be a height >= 0 in metres, got {args.air_gap:g}")
    if args.air_gap > 0 and args.method not in ("kirchhoff", "backprojection"):
        raise GPR3DError(f"--air-gap needs --method kirchhoff or backprojection (refraction at the surface), not "
                         f"{args.method}")
    out = _out_folder(args.out, "migrate")
    eps = _eps_argument(args.eps_r) if args.eps_r is not None else (0.299792458 / args.velocity) ** 2
    s = _apply_steps(_read_channel(args), args.steps)
    if eps == "file":
        if s.eps_r is None:
            raise GPR3DError(f"--eps-r file: {args.input} gives no eps_r; give a number")
        eps = s.eps_r
    prof = migrate_profile(s, eps_r=float(eps), method=args.method, max_depth_m=args.max_depth,
                           spacing_m=args.spacing, trace_spacing_m=args.trace_spacing, air_gap_m=args.air_gap)
    from gpr3d.io.resultdir import result_folder

    with result_folder(out, command="migrate") as stage:
        write_profile(stage / "profile.h5", prof)
        save_profile_png(stage / "profile.png", prof, title=f"{Path(args.input).name}: {args.method}, eps_r {eps:.3g}")
    print(f"wrote {out}/profile.h5 and profile.png: {prof.image.shape[0]} x {prof.image.shape[1]} cells "
          f"({args.method}, eps_r {eps:.3g}, {prof.wall_s:.1f} s)")
    return 0


def cmd_simulate(args):
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset

    _writable(args.out, "--out")
    cfg = SimulateConfig(out=args.out, n=args.n, seed=args.seed, engine=args.engine, workers=args.workers,
                         scheduler=args.scheduler, image_height=args.image_height, preset=args.preset,
                         host=args.host, start=args.start, max_seconds=args.max_seconds)
    summary = build_dataset(cfg, progress=not args.no_progress)
    if summary["samples_per_s"]:
        print(f"throughput: {summary['samples_per_s'] * 3600:.0f} samples/hour "
              f"({summary['mean_sample_wall_s']:.1f} s per sample per worker)")
    return 0


def cmd_pose(args):
    from gpr3d.io.inertial import (read_imu_csv, read_rig, read_wheel_csv, relative_from_camera_poses,
                                   write_imu_csv, write_rig, write_wheel_csv)
    from gpr3d.io.trajectory import read_trajectory, write_tum

    out = Path(args.out)
    if args.action == "simulate":
        from scipy.spatial.transform import Rotation

        from gpr3d.core.trajectory import Trajectory
        from gpr3d.pose.rig import RigConfig, simulate_rig

        _in_range(args.duration, "--duration", 20, MAX_SIMULATED_S, "seconds of motion")
        run = simulate_rig(RigConfig(duration_s=args.duration, vo_gap=(args.duration / 2, 2.0)), seed=args.seed)
        from gpr3d.io.resultdir import result_folder

        _writable(out, "--out")
        cfg = run.config
        keep = run.vo.valid.copy()  # frames whose motion from the one before is known; lost ones are left out
        keep[0] = True
        Rc, pc = run.vo.chained()
        cam = Trajectory(run.vo.t_s[keep], pc[keep], Rotation.from_matrix(Rc[keep]).as_quat()[:, [3, 0, 1, 2]])
        wrote = "imu.csv, odometry.tum (camera poses), wheel.csv, truth.tum (antenna) and rig.json"
        with result_folder(out, command="pose simulate") as stage:
            write_imu_csv(run.imu, stage / "imu.csv")
            write_tum(cam, stage / "odometry.tum")
            write_wheel_csv(*run.wheel(), stage / "wheel.csv")
            write_tum(run.truth_trajectory(), stage / "truth.tum")
            write_rig(stage / "rig.json", imu_T_camera=cfg.imu_T_camera, imu_T_antenna=cfg.imu_T_antenna,
                      camera_time_offset_s=cfg.camera_time_offset_s)
            if args.bag:
                from gpr3d.io.rosbag import write_bag

                write_bag(stage / "bag", imu=run.imu, trajectory=cam)
                wrote += ", bag/ (ROS 2: /imu, /odometry)"
        print(f"wrote {wrote} to {out}/: {run.path_length_m:.1f} m in {args.duration:g} s, odometry lost for 2 s at "
              f"{args.duration / 2:g} s ({int(keep.sum())} odometry frames)")
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
    rig = read_rig(args.rig) if args.rig else {}
    vo = None
    source = args.imu or args.bag
    if args.bag:
        from gpr3d.io.rosbag import bag_topics, iter_bag_rgbd, read_bag_camera_info, read_bag_imu, read_bag_trajectory

        imu = read_bag_imu(args.bag, args.imu_topic)
        if args.colour_topic:
            from gpr3d.pose.vo import OdometryConfig, require_open3d, rgbd_odometry

            require_open3d()
            intr = read_bag_camera_info(args.bag, args.camera_info_topic)
            vo, rep = rgbd_odometry(iter_bag_rgbd(args.bag, args.colour_topic, args.depth_topic), intr,
                                    OdometryConfig(keyframe_m=args.keyframe))
            lost = ", ".join(f"{k} {v}" for k, v in rep["lost"].items()) or "none"
            print(f"RGB-D odometry: {rep['registered']} of {rep['frames'] - 1} frames registered to "
                  f"{rep['keyframes']} keyframes (lost: {lost}), {rep['s_per_frame'] * 1e3:.0f} ms a frame")
        elif args.odometry_topic or any(m in ("geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry",
                                              "geometry_msgs/msg/PoseWithCovarianceStamped")
                                        for _, m, _ in bag_topics(args.bag)):
            vo = relative_from_camera_poses(read_bag_trajectory(args.bag, args.odometry_topic), rot_sigma_deg=sig[0],
                                            trans_frac=sig[1], trans_floor_m=sig[2])
    else:
        imu = read_imu_csv(args.imu)
        if args.odometry:
            vo = relative_from_camera_poses(read_trajectory(args.odometry), rot_sigma_deg=sig[0], trans_frac=sig[1],
                                            trans_floor_m=sig[2])
    wheel = read_wheel_csv(args.wheel) if args.wheel else None
    from gpr3d.pose.eskf import EskfConfig, fuse

    if args.estimate_offset:
        if vo is None:
            raise GPR3DError("--estimate-offset needs odometry (--odometry, or odometry in the bag)")
        from gpr3d.pose.sync import estimate_time_offset

        off = estimate_time_offset(imu, vo)
        if off["at_search_edge"]:
            raise GPR3DError(f"the camera-IMU offset lies beyond +-0.2 s (search edge {off['offset_s']:+.3f} s): "
                             "check the two clocks")
        print(f"camera-IMU time offset estimated: {off['offset_s'] * 1e3:+.1f} ms from {off['frames']} frames "
              f"({off['turn_deg']:.0f} deg of turns)" + (f"; the rig file says {rig['camera_time_offset_s'] * 1e3:+.1f} ms"
                                                          if "camera_time_offset_s" in rig else ""))
        rig["camera_time_offset_s"] = off["offset_s"]
    cfg = EskfConfig(init_still_s=args.still, flat_ground_sigma_m=args.flat_ground, **rig)
    res = fuse(imu, vo, cfg, wheel=wheel, smooth=args.smooth)
    if args.loops:
        import numpy as np

        from gpr3d.pose.graph import close_loops
        from gpr3d.pose.vo import loop_candidates, rgbd_loop_closures

        pairs = loop_candidates(res)
        # the fusion's frames are odometry's frames inside the IMU record: find each one's place in the bag
        vo_idx = np.searchsorted(vo.t_s + cfg.camera_time_offset_s, res.frame_t_s - 1e-9)
        need = {int(vo_idx[k]) for pair in pairs for k in pair}
        kept = {k: (c, d) for k, (_, c, d) in enumerate(iter_bag_rgbd(args.bag, args.colour_topic, args.depth_topic))
                if k in need}
        closures, lrep = rgbd_loop_closures(lambda k: kept[int(vo_idx[k])], res, intr, cfg.imu_T_camera,
                                            candidates=pairs)
        grep_ = {}
        res = close_loops(res, closures, report=grep_)
        print(f"loop closures: {lrep['closures']} registered of {lrep['candidates']} revisits; "
              f"{grep_.get('used', 0)} used, {grep_.get('gated', 0)} + {grep_.get('rejected', 0)} left out as wrong")
    traj = res.antenna_trajectory()
    write_tum(traj, out)
    msg = (f"wrote {out}: {len(traj)} antenna poses; odometry frames used {int(res.vo_used.sum())}, gated out "
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


def cmd_dataset(args):
    from gpr3d.simulation.packed import PackedDataset, load_sample, pack_dataset, save_label_preview

    if args.action == "preview":
        _check_suffix(args.dst, (".png",), "dataset preview's output (dst)")
        survey, labels = load_sample(args.src, args.index)
        save_label_preview(survey, labels, args.dst)
        print(f"wrote {args.dst}")
    elif args.action == "pack":
        regen = args.regenerate or ""
        info = pack_dataset(args.src, args.dst, n_samples=args.n_samples, regenerate=regen)
        print(f"packed {info['n']} samples into {info['file']} ({info['bytes'] / 1e6:.1f} MB)")
    else:
        from gpr3d.io.resultdir import result_folder

        ds = PackedDataset(args.src)
        _out_folder(args.dst, "dataset export")
        with result_folder(args.dst, command="dataset export") as stage:  # all the images and coco.json, or none
            coco = ds.export_coco(stage, image_height=args.image_height)
        print(f"wrote {len(coco['images'])} images and {len(coco['annotations'])} boxes to {args.dst}/")
    return 0


def _reconstruct_defaults():
    """The library's reconstruction defaults (the CLI's defaults come from them, so the two cannot drift apart)."""
    from gpr3d.migration.config import ReconstructConfig

    return ReconstructConfig()


#: ReconstructConfig's names for the settings that reconstruct's options set
_RECONSTRUCT_FLAGS = {"spacing_m": "--spacing", "max_depth_m": "--max-depth", "aperture_deg": "--aperture",
                      "threshold": "--threshold", "min_line_m": "--min-line", "engine": "--engine",
                      "min_target_depth_m": "--min-depth", "method": "--method", "tile_m": "--tile",
                      "air_gap_m": "--air-gap"}


def cmd_reconstruct(args):
    from gpr3d.io.detections import read_boxes
    from gpr3d.io.registry import read
    from gpr3d.io.trajectory import attach_poses, read_trajectory
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct, write_reconstruction
    from gpr3d.migration.targets import target_name

    if args.mask == "detect" and args.boxes:
        raise GPR3DError("give --boxes or --mask detect, not both")
    _out_folder(args.out, "reconstruct")
    site = dict(tile_m=args.tile, workers=args.workers, scheduler=args.scheduler,
                checkpoint=str(Path(args.out) / "tiles") if args.resume else None)
    from gpr3d.migration.reconstruct import check_config

    if args.aperture < 0:
        raise GPR3DError(f"--aperture must be 0 (none) or a cone half-angle in (0, 90) degrees, got {args.aperture:g}")
    if args.tile is not None and args.spacing > 0 and math.isfinite(args.spacing):
        # a tile of a few voxels spends its time on its margins (0.0001 m once ran 41,000 one-voxel tiles)
        _in_range(args.tile, "--tile", 10 * args.spacing, 1e5, f"a tile side in metres, at least 10 voxels of "
                                                                f"--spacing {args.spacing:g}")
    settings = dict(spacing_m=args.spacing, max_depth_m=args.max_depth,
                    aperture_deg=None if args.aperture == 0 else args.aperture, threshold=args.threshold,
                    min_line_m=args.min_line, engine=args.engine, time_zero="none" if args.no_time_zero else "peak",
                    min_target_depth_m=args.min_depth, method=args.method, air_gap_m=args.air_gap)
    check_config(ReconstructConfig(**settings, **site), names=_RECONSTRUCT_FLAGS)  # one line, before any work
    eps_given = _eps_argument(args.eps_r)
    estimate = eps_given is None
    if args.radius is not None and not estimate:
        raise GPR3DError("--radius is used to estimate eps_r: leave --eps-r out, or leave --radius out")
    _check_radius(args, args.depth)
    # weights checked before the work starts
    detector = _detector(args) if args.mask == "detect" or (estimate and not args.boxes) else None
    depthnet = _depthnet(args) if estimate and args.depth in ("hybrid", "net") else None
    survey = _with_track(read(args.input, format=args.format, channel=args.channel), args)
    if args.poses:
        traj = read_trajectory(args.poses)
        if len(traj) != survey.n_traces:
            raise GPR3DError(f"--poses {args.poses} holds {len(traj)} poses but {args.input} has {survey.n_traces} "
                             "traces (one pose per trace)")
        survey = attach_poses(survey, traj, by="index")
    if survey.positions_xyz is None:
        raise GPR3DError("the survey has no antenna positions: give --poses (a TUM file, one pose per trace)")
    if eps_given == "file" and survey.eps_r is None:
        raise GPR3DError(f"--eps-r file: {args.input} gives no eps_r; give a number or leave --eps-r out to estimate it")
    cfg = ReconstructConfig(eps_r=survey.eps_r if eps_given == "file" else eps_given, **settings, **site)
    boxes = read_boxes(args.boxes) if args.boxes else None
    if args.boxes and not boxes:
        raise GPR3DError(f"{args.boxes} lists no boxes: nothing to migrate inside them (leave --boxes out to "
                         "migrate the whole record)")
    found = None
    if args.boxes:
        from gpr3d.io.detections import read_detections
        from gpr3d.migration.masking import check_boxes

        check_boxes(boxes, survey.n_traces, survey.n_samples * survey.dt_s)  # one line, before any estimate
        found = {"input": str(args.input),
                 "targets": _checked_targets(args.boxes, read_detections(args.boxes)[0]["targets"], survey)}
    if detector is not None:
        found = detector.detect(survey, score_threshold=args.score, input_name=str(args.input))
    if estimate:
        _add_depths(survey, found, args.depth, depthnet, args.trace_spacing, args.radius)
        if "permittivity" not in found:
            raise GPR3DError(f"{args.input}: eps_r cannot be estimated without trace positions; give --eps-r "
                             "or --trace-spacing")
        p = found["permittivity"]
        cfg = replace(cfg, eps_r=float(p["eps_r"]))
        parts = "; ".join(f"{k} {p[k]['eps_r']:.2f}" for k in ("net", "fit") if k in p and p[k]["eps_r"] == p[k]["eps_r"])
        header = f"; the file's header says {survey.eps_r:g}" if survey.eps_r else ""
        print(f"eps_r {p['eps_r']:.2f} +- {p['sigma_eps_r']:.2f} estimated from the data ({args.depth}"
              f"{': ' + parts if parts else ''}){header}")
    else:
        print(f"eps_r {cfg.eps_r:g} ({'the file header' if eps_given == 'file' else 'given'})")
    if args.mask == "detect":
        boxes = [t["box"] for t in found["targets"]]
        print(f"detector: {len(boxes)} boxes in {survey.n_traces} traces ({found['wall_s']:.1f} s)")
        if not boxes:
            raise GPR3DError("the detector found no hyperbolas: nothing to migrate (try a lower --score)")
    result = reconstruct(survey, cfg, boxes=boxes, log=print)
    result.eps_r_source = f"estimated ({args.depth})" if estimate else ("file header" if eps_given == "file" else "given")
    from gpr3d.io.resultdir import result_folder

    with result_folder(args.out, command="reconstruct") as stage:  # the whole result, or the previous one
        if args.mask == "detect":
            from gpr3d.io.detections import write_detections

            write_detections([found], stage / "detections.json")
        files = write_reconstruction(result, stage, source=str(args.input))
    g = result.grid
    rate = f" ({result.updates_per_s / 1e9:.2f} G voxel-trace updates/s)" if result.updates_per_s else ""
    how = "line by line (pseudo-3D)" if args.method == "pseudo3d" else "onto"
    print(f"migrated {result.n_traces} traces {how} {g.nx} x {g.ny} x {g.nd} voxels in "
          f"{result.timings_s['migrate']:.1f} s{rate}")
    if result.frame is not None:
        print("one straight profile: migrated in 2D (the vertical plane under it); targets crossing it are points")
    for i, t in enumerate(result.targets):
        pts = "  ".join("(" + ", ".join(f"{v:.2f}" for v in p) + ")" for p in t.points_xyz)
        print(f"  {target_name(i):>4} {t.kind:5s} depth {t.depth_m:.2f} m  score {t.score:.2f}  {pts}")
    print(f"wrote {', '.join(files)} to {args.out}/")
    return 0


def _eps_argument(value):
    """``--eps-r``: None (estimate from the data), ``"file"`` (the header's) or a number >= 1."""
    if value is None or value == "file":
        return value
    try:
        eps = float(value)
    except ValueError:
        raise GPR3DError(f"--eps-r must be a relative permittivity >= 1 or 'file', got {value!r}") from None
    if not (eps >= 1.0 and eps < 1e4):
        raise GPR3DError(f"--eps-r must be a relative permittivity >= 1 or 'file', got {value!r}")
    return eps


def _check_suffix(path, suffixes, what):
    """An output file's name: its suffix, and a folder it can be written in (before any work)."""
    if path and Path(path).suffix.lower() not in suffixes:
        raise GPR3DError(f"{what} {path}: expected a {' or '.join(suffixes)} file")
    if path:
        _writable(path, what)


def _detector(args):
    from gpr3d.detection.infer import load_detector

    if not 0.0 <= args.score <= 1.0:
        raise GPR3DError(f"--score must lie in 0..1, got {args.score}")
    return load_detector(args.weights, device=args.device, engine=args.runtime)


def cmd_detect(args):
    from gpr3d.io.detections import write_detections
    from gpr3d.io.registry import read_all

    _check_suffix(args.out, (".json",), "--out")
    _check_suffix(args.overlay, (".png",), "--overlay")
    _check_radius(args, args.depth)
    from gpr3d.io.userlabels import IMAGE_SUFFIXES, read_picture

    picture = Path(args.input).suffix.lower() in IMAGE_SUFFIXES
    if picture:
        read_picture(args.input, args.pixel_map)  # a picture without a time axis fails before the model loads
    elif args.pixel_map is not None:
        raise GPR3DError(f"--pixel-map is for pictures (PNG, JPG, ...); {args.input} is a radar file")
    det = _detector(args)  # weights checked before the recording is read
    depthnet = _depthnet(args) if args.depth in ("hybrid", "net") else None
    surveys = [read_picture(args.input, args.pixel_map, frequency_hz=args.frequency)] if picture else \
        read_all(args.input, format=args.format)
    results = [det.detect(s, score_threshold=args.score, input_name=str(args.input)) for s in surveys]
    if args.depth != "none":
        for s, r in zip(surveys, results):
            _add_depths(s, r, args.depth, depthnet, args.trace_spacing, args.radius)
    write_detections(results, args.out)
    for r in results:
        ch = f" channel {r['channel']}" if len(results) > 1 else ""
        print(f"{args.input}{ch}: {len(r['targets'])} targets in {r['n_traces']} traces "
              f"({r['n_windows']} windows, {r['wall_s']:.2f} s)")
        perm = r.get("permittivity")
        if perm:
            print(f"  host eps_r {perm['eps_r']:.2f} +- {perm['sigma_eps_r']:.2f} ({perm['method']})")
        for t in r["targets"]:
            extra = f"  depth {t['depth_m']:.3f} m" if t.get("depth_m") is not None else ""
            extra += f"  x {t['x_m']:.2f} m" if t.get("x_m") is not None else ""
            kind = f"  {t['kind']} ({t['kind_score']:.2f})" if t.get("kind_score") is not None else ""
            print(f"  trace {t['apex_trace']:5d}  {t['apex_time_s'] * 1e9:8.2f} ns  score {t['score']:.2f}{kind}{extra}")
    if args.overlay:
        from gpr3d.viz.bscan import save_bscan_png

        s = surveys[0]
        shown = s.dewow().remove_background()
        save_bscan_png(shown, args.overlay, cmap="gray", boxes=[t["box"] for t in results[0]["targets"]],
                       apexes=[(t["apex_trace"], t["apex_time_s"]) for t in results[0]["targets"]],
                       title=f"{Path(args.input).name}: {len(results[0]['targets'])} detections (score >= {args.score})")
    print(f"wrote {args.out}" + (f" and {args.overlay}" if args.overlay else ""))
    return 0


def _depthnet(args):
    from gpr3d.inversion.depthnet import DepthEstimator

    return DepthEstimator.load(args.depthnet, device=args.device)


def _check_radius(args, method: str) -> None:
    """``--radius``: a number of metres in 0..50, for a method that fits hyperbolas."""
    import math

    r = args.radius
    if r is None:
        return
    if not (math.isfinite(r) and 0.0 <= r <= 50.0):
        raise GPR3DError(f"--radius must be a radius in metres in 0..50, got {r}")
    if method not in ("fit", "hybrid"):
        raise GPR3DError(f"--radius is used by the hyperbola fit: give it with fit or hybrid, not {method}")


def _add_depths(survey, result: dict, method: str, depthnet, trace_spacing_m, radius_m=None) -> None:
    """Host eps_r and each target's depth (and position) into a ``detect`` result, in place."""
    import math

    from gpr3d.inversion.estimate import estimate_depths

    if trace_spacing_m is None and survey.distances_m is None:
        warnings.warn(f"{result['input']}: the file has no trace positions; no depths or eps_r "
                      "(give --trace-spacing)")
        return
    if not result["targets"] and method == "fit":
        return
    est = estimate_depths(survey, result["targets"], method=method, estimator=depthnet,
                          trace_spacing_m=trace_spacing_m, radius_m=radius_m)
    p = est["permittivity"]
    result["permittivity"] = {"eps_r": p["eps_r"], "sigma_eps_r": p["sigma_eps_r"], "method": method,
                              **{k: p[k] for k in ("net", "fit") if k in p}}
    for t, e in zip(result["targets"], est["targets"]):
        t["x_m"] = e["x_m"]
        t["depth_m"] = e["depth_m"] if math.isfinite(e["depth_m"]) else None
        t["sigma_depth_m"] = e["sigma_depth_m"] if math.isfinite(e["sigma_depth_m"]) else None


def _checked_targets(path, targets, survey) -> list[dict]:
    """Targets read from a detections file, their boxes checked against the record (one line naming the first
    bad one); an apex that is not a pair of finite numbers is dropped (the box's own is used)."""
    import math

    from gpr3d.migration.masking import check_boxes

    try:
        boxes = check_boxes([t["box"] for t in targets], survey.n_traces, survey.n_samples * survey.dt_s)
    except GPR3DError as exc:
        raise GPR3DError(f"{path}: {exc}") from None
    out = []
    n, window = survey.n_traces, (survey.n_samples - 1) * survey.dt_s
    for t, b in zip(targets, boxes):  # boxes reaching past the record are cut to it
        t = dict(t, box=[max(b[0], 0.0), max(b[1], 0.0), min(b[2], n - 1.0), min(b[3], window)])
        a = (t.get("apex_trace"), t.get("apex_time_s"))
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in a):
            t.pop("apex_trace", None)
            t.pop("apex_time_s", None)
        out.append(t)
    return out


def cmd_depth(args):
    from gpr3d.io.detections import read_detections
    from gpr3d.io.registry import read

    if args.trace_spacing is not None and not args.trace_spacing > 0:
        raise GPR3DError(f"--trace-spacing must be a positive number of metres, got {args.trace_spacing}")
    _check_suffix(args.out, (".json",), "--out")
    _check_radius(args, args.method)
    det = _detector(args) if not args.boxes else None
    depthnet = _depthnet(args) if args.method in ("hybrid", "net") else None
    survey = read(args.input, format=args.format, channel=args.channel)
    if args.boxes:
        chans = read_detections(args.boxes)
        if not 0 <= args.channel < len(chans):
            raise GPR3DError(f"{args.boxes}: has {len(chans)} channel(s); no channel {args.channel}")
        found = {"input": str(args.input), "targets": _checked_targets(args.boxes, chans[args.channel]["targets"],
                                                                      survey)}
    else:
        found = det.detect(survey, score_threshold=args.score, input_name=str(args.input))
    if survey.distances_m is None and args.trace_spacing is None:
        raise GPR3DError(f"{args.input}: the file has no trace positions; give --trace-spacing (m)")
    _add_depths(survey, found, args.method, depthnet, args.trace_spacing, args.radius)
    p = found["permittivity"]
    print(f"{args.input}: host eps_r {p['eps_r']:.2f} +- {p['sigma_eps_r']:.2f} ({args.method}"
          + "".join(f"; {k} {p[k]['eps_r']:.2f}" for k in ("net", "fit") if k in p) + ")")
    print("| target | trace | x m | apex ns | depth to top m | +- m |")
    print("|---|---|---|---|---|---|")
    for k, t in enumerate(found["targets"]):
        d, sd = t.get("depth_m"), t.get("sigma_depth_m")
        print(f"| {k} | {t.get('apex_trace', '')} | {t['x_m']:.3f} | "
              f"{t['apex_time_s'] * 1e9 if t.get('apex_time_s') is not None else float('nan'):.2f} | "
              f"{d if d is not None else float('nan'):.3f} | {sd if sd is not None else float('nan'):.3f} |")
    if args.out:
        from gpr3d.io.detections import write_detections

        write_detections([found], args.out)
        print(f"wrote {args.out}")
    return 0


def _labels_provenance(labels) -> dict:
    """The user's label files (and the files they name) by SHA-256, for the weights' provenance."""
    if not labels:
        return {}
    import hashlib

    p = Path(labels)
    files = sorted(p.glob("*.xml")) if p.is_dir() else [p]
    return {"labels": str(p), "labels_sha256": {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in files}}


def cmd_train_depthnet(args):
    """``gpr3d train depthnet``: forward-model records (and packed gprMax ones) prepared once, then trained."""
    from dataclasses import asdict

    from gpr3d.inversion.depthnet import (DepthTrainConfig, cache_depth_records, load_depth_records, save_depthnet,
                                          train_depthnet, validate_depthnet)
    from gpr3d.simulation.surveys import SurveySource

    if args.records < 1:
        raise GPR3DError(f"--records must be at least 1, got {args.records}")
    if args.init == "default":
        raise GPR3DError("--init default: the package ships DepthNet as ONNX; start from its PyTorch twin, "
                         "references/depthnet/default_depthnet.pt")
    if args.max_seconds is not None and not args.max_seconds > 0:
        raise GPR3DError(f"--max-seconds must be positive, got {args.max_seconds}")
    from gpr3d.inversion.depthnet import DepthConfig

    net = DepthConfig(arch=args.arch, width=args.width)
    cfg = DepthTrainConfig(out=args.out, steps=args.steps or 2000, batch=args.batch or 16, lr=args.lr,
                           optimiser=args.optimiser, seed=args.seed, device=args.device,
                           checkpoint_every=args.checkpoint_every, net=asdict(net), init=args.init)
    if cfg.init:  # a wrong file fails here, in one line, before the records are prepared
        from gpr3d.inversion.depthnet import load_depthnet

        load_depthnet(cfg.init)
    packed = []
    if args.packed:
        from gpr3d.detection.data import PackedSource

        for item in args.packed:  # each checked in one line before any work
            part = PackedSource(item, holdout=args.packed_holdout).parts[0]
            packed.append((Path(item.rpartition(":")[0] if ":" in item else item).stem, part))
    out = Path(args.out)
    seed = 2000 if args.data_seed is None else args.data_seed  # apart from the detector's (1000) and tests' (777)
    folders = [cache_depth_records(SurveySource(seed), range(args.records), out / f"records_forward_{seed}")]
    for name, (ds, n) in packed:
        folders.append(cache_depth_records(lambda i, ds=ds: ds[i], range(n), out / f"records_{name}"))
    records = load_depth_records(folders[0])
    for f in folders[1:]:  # each packed set repeated to about a quarter of the forward records (at least once)
        recs = load_depth_records(f)
        records += recs * max(1, round(args.records / 4 / max(len(recs), 1)))
    res = train_depthnet(cfg, records, progress=not args.no_progress, max_seconds=args.max_seconds)
    val = validate_depthnet(res["model"], res["net"], SurveySource(seed + 1), 40)
    weights = out / "depthnet.pt"
    cmd = "gpr3d " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("gpr3d") else "gpr3d train depthnet"
    save_depthnet(res["model"], res["net"], weights,
                  provenance={"command": cmd, "config": asdict(cfg), "train_wall_s": res["wall_s"],
                              "steps_done": res["steps"], "parameters": res["parameters"],
                              "data": [f"survey_sample(seed={seed}, i < {args.records})"] + list(args.packed or []),
                              "validation": val})
    print(f"trained DepthNet ({res['parameters']} parameters) for {res['steps']} steps in {res['wall_s']:.0f} s; "
          f"validation eps_r relative RMSE {val['eps_rel_rmse']:.3f}, depth MAE {val['depth_mae_m']:.3f} m; "
          f"wrote {weights}")
    return 0


def _in_range(value, flag: str, lo, hi, what: str) -> None:
    """One line for a numeric option outside its plausible range (None: not given, nothing to check)."""
    if value is None:
        return
    if not (math.isfinite(value) and lo <= value <= hi):
        raise GPR3DError(f"{flag} must be {what} ({lo:g}..{hi:g}), got {value:g}")


def _check_train_args(args) -> None:
    """train's numbers, before any data or model is made (a 0 once meant 'the default': hours of training)."""
    _in_range(args.steps, "--steps", 1, 10**7, "a number of optimiser steps")
    _in_range(args.batch, "--batch", 1, 4096, "a number of windows per step")
    _in_range(args.lr, "--lr", 1e-9, 10.0, "a positive learning rate")
    _in_range(args.warmup, "--warmup", 0, 10**7, "a number of steps")
    _in_range(args.workers, "--workers", 0, 256, "a number of data-loading processes")
    _in_range(args.checkpoint_every, "--checkpoint-every", 1, 10**7, "a number of steps")
    _in_range(args.max_seconds, "--max-seconds", 1e-3, 1e9, "a positive time in seconds")
    # (--labels-fraction and --packed-fraction: TrainConfig says 0..1 in its own words)
    _in_range(args.packed_holdout, "--packed-holdout", 0, 10**7, "a number of records")
    _in_range(args.width, "--width", 1, 1024, "a number of channels")
    _writable(args.out, "--out")


def cmd_train(args):
    from dataclasses import asdict

    _check_train_args(args)
    if args.what == "depthnet":
        return cmd_train_depthnet(args)

    from gpr3d.detection.train import TrainConfig, train_detector
    from gpr3d.detection.weights import save_weights
    from gpr3d.simulation.surveys import SurveySource

    if args.max_seconds is not None and not args.max_seconds > 0:
        raise GPR3DError(f"--max-seconds must be positive, got {args.max_seconds}")
    cfg = TrainConfig(out=args.out, model=args.model, steps=args.steps or 3000, batch=args.batch or 8, lr=args.lr,
                      optimiser=args.optimiser, warmup=args.warmup, seed=args.seed,
                      data_seed=1000 if args.data_seed is None else args.data_seed,
                      device=args.device,
                      workers=args.workers, checkpoint_every=args.checkpoint_every, init=args.init,
                      packed=args.packed, packed_fraction=args.packed_fraction, packed_holdout=args.packed_holdout,
                      labels=args.labels, labels_fraction=args.labels_fraction, pixel_map=args.pixel_map,
                      labels_names=_names_list(args.class_names), labels_kinds=args.class_kinds,
                      labels_frequency_hz=args.labels_frequency, kinds=_names_list(args.kinds), freeze=args.freeze)
    if cfg.packed:  # a wrong packed file (or hold-out) fails in one line before any model is built
        from gpr3d.detection.data import PackedSource

        PackedSource(cfg.packed, holdout=cfg.packed_holdout)
    if cfg.labels:  # a wrong label file fails in one line before any model is built
        _read_labels(args, cfg.labels)
    res = train_detector(cfg, SurveySource(cfg.data_seed), progress=not args.no_progress,
                         max_seconds=args.max_seconds)
    weights = Path(args.out) / "weights.pt"
    cmd = "gpr3d " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("gpr3d") else "gpr3d train detector"
    save_weights(res["model"], cfg.model, cfg.window, weights, kinds=res.get("kinds"),
                 provenance={"name": cfg.model, "command": cmd, "config": asdict(cfg), "train_wall_s": res["wall_s"],
                             "device": cfg.device, "data": f"survey_sample(seed={cfg.data_seed}, i)",
                             "steps_done": res["steps"], **_labels_provenance(cfg.labels)})
    print(f"trained {cfg.model} for {res['steps']} steps in {res['wall_s']:.0f} s; wrote {weights}")
    return 0


def _names_list(text):
    """``"a,b"`` -> ``["a", "b"]`` (``None`` stays ``None``); an empty name is refused."""
    if text is None:
        return None
    names = [n.strip() for n in str(text).split(",")]
    if not all(names):
        raise GPR3DError(f"a list of names must be comma-separated words, got {text!r}")
    return names


def _read_labels(args, path, split: str = "train"):
    from gpr3d.io.labelled import read_labelled

    return read_labelled(path, pixel_map=args.pixel_map, split=split, names=_names_list(args.class_names),
                         kinds=args.class_kinds, frequency_hz=args.labels_frequency)


def _eval_records(args):
    """The labelled records ``gpr3d eval`` judges on, and their description (checked before any model loads)."""
    if args.n is not None and args.n < 1:
        raise GPR3DError(f"--n must be at least 1, got {args.n}")
    if args.seed < 0:
        raise GPR3DError(f"--seed must be 0 or more, got {args.seed}")
    if getattr(args, "labels", None) is not None:
        if args.data is not None:
            raise GPR3DError("give --data or --labels, not both")
        recs = _read_labels(args, args.labels, args.split)
        recs = recs[: args.n] if args.n else recs
        return recs, f"{args.labels} ({len(recs)} labelled B-scans)"
    if args.data is not None:
        from gpr3d.io.packed import PackedDataset, labelled_records

        src = Path(args.data)
        if not src.exists():
            raise GPR3DError(f"--data {src}: no such file or folder")
        if src.is_file():
            PackedDataset(src)  # a wrong file fails here, in one line, before the model loads
        elif not (src / "samples").is_dir():
            raise GPR3DError(f"--data {src}: neither a packed dataset nor a gpr3d simulate folder (no samples/)")
        return labelled_records(src, n=args.n), f"{src} ({'first ' + str(args.n) if args.n else 'all'} records)"
    from gpr3d.simulation.surveys import survey_sample

    n = args.n or 60
    return (survey_sample(args.seed, i) for i in range(n)), f"held-out survey-scale forward-model set (seed {args.seed})"


def cmd_eval(args):
    records, what = _eval_records(args)
    if args.what == "depth":
        from gpr3d.inversion.depthnet import DepthEstimator
        from gpr3d.inversion.evaluate import depth_rows, depth_table

        est = DepthEstimator.load(args.depthnet, device=args.device)
        rows = depth_rows(records, estimator=est)
        print(f"{what}: {len({r['record'] for r in rows})} records, labelled boxes")
        print("\n".join(depth_table(rows)))
        return 0
    from gpr3d.detection.evaluate import evaluate_detector

    det = _detector(args)
    m = evaluate_detector(det, records, score_threshold=args.score)
    print(f"{what}: {m['n_records']} records, {m['n_true']} targets")
    print("| mAP@0.75 | mAP@0.5 | AR@10 | AR@100 | apex recall | false / true | s per window |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {m['mAP@0.75']:.3f} | {m['mAP@0.5']:.3f} | {m['AR@10']:.3f} | {m['AR@100']:.3f} | "
          f"{m['apex_recall']:.3f} | {m['false_per_true']:.3f} | {m['s_per_window']:.3f} |")
    print(f"class-agnostic: mAP@[.5:.95] {m['mAP']:.3f}, recall@0.5 {m['recall@0.5']:.3f}")
    if "by_kind" in m:
        k = m["by_kind"]
        print(f"class-averaged ({', '.join(k['kinds'])}): mAP@0.5 {k['mAP@0.5']:.3f}, mAP@0.75 {k['mAP@0.75']:.3f}, "
              f"mAP@[.5:.95] {k['mAP']:.3f}, AR@100 {k['AR@100']:.3f}, recall@0.5 {k['recall@0.5']:.3f}")
    print("apex recall by kind: " + ", ".join(f"{k} {v['recall']:.2f} ({v['found']}/{v['n']})"
                                              for k, v in m["apex_recall_by_kind"].items()))
    return 0


def cmd_demo(args):
    from gpr3d.demo import DemoConfig, run_demo

    run_demo(args.out, DemoConfig(input=args.input))
    return 0


class _Parser(argparse.ArgumentParser):
    """An epilog given as a function is made when the help is shown (the steps' list imports all of processing)."""

    def format_help(self):
        if callable(self.epilog):
            self.epilog = self.epilog()
        return super().format_help()

    def error(self, message):
        """One line: what is wrong, and where the usage is (argparse would print the whole usage first)."""
        self.exit(2, f"{self.prog}: error: {message} (usage: {self.prog} --help)\n")


def _steps_help() -> str:
    from gpr3d.processing.steps import describe_steps

    return "processing steps, each NAME[:key=value[:key=value]] (SI units); known steps:\n" + describe_steps()


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="gpr3d",
        description="Find and reconstruct buried objects from ground-penetrating radar.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"gpr3d {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    def add(name, func, help_, epilog=None):
        sp = sub.add_parser(name, help=help_, description=help_, epilog=epilog,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
        sp.set_defaults(func=func)
        return sp

    def add_detector_args(sp):
        sp.add_argument("--weights", default=None, help="detector weights (default: the shipped model)")
        sp.add_argument("--score", type=float, default=0.5, help="keep detections scoring at least this (0..1)")
        sp.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:N")
        sp.add_argument("--runtime", default="auto", choices=("auto", "torch", "onnx"),
                        help="auto (default: ONNX Runtime for the shipped model on the CPU, else PyTorch), "
                             "torch, or onnx (an .onnx export; no PyTorch import, faster start)")

    def add_depth_args(sp, flag):
        sp.add_argument(flag, default="hybrid", choices=("hybrid", "net", "fit") + (("none",) if flag == "--depth" else ()),
                        help="host eps_r and depths: hybrid (default: DepthNet refined by the hyperbola fit "
                             "where they agree), "
                             "net (DepthNet), fit (classical hyperbola fit)" + (", none" if flag == "--depth" else ""))
        sp.add_argument("--depthnet", default=None, help="DepthNet weights (default: the shipped ones)")
        sp.add_argument("--trace-spacing", type=float, default=None,
                        help="trace spacing in metres (default: the file's positions)")
        sp.add_argument("--radius", type=float, default=None, metavar="M",
                        help="the targets' radius in metres when known (e.g. 0.008 for 16 mm rebar): the hyperbola "
                             "fit then takes that cylinder instead of a point, which reads eps_r low by about "
                             "radius / (depth + radius)")

    def add_label_args(sp):
        sp.add_argument("--pixel-map", default=None,
                        help="time axis of labelled pictures: s_per_px=SECONDS[,t0_s=..,traces_per_px=..,trace0=..] "
                             "(P-GPR: s_per_px=3.125e-11, 8 ns over 256 rows)")
        sp.add_argument("--class-names", default=None, metavar="A,B",
                        help="YOLO class names in id order when the dataset has no data.yaml (P-GPR: steel,pipe)")
        sp.add_argument("--class-kinds", default=None, metavar="NAME=KIND,..",
                        help="map class names onto target kinds (P-GPR: pipe=pvc_pipe; steel is rebar already)")
        sp.add_argument("--labels-frequency", type=float, default=None, metavar="HZ",
                        help="antenna frequency of labelled pictures (P-GPR: 1.6e9)")

    def add_marks(sp):
        sp.add_argument("--marks-every", type=float, default=None, metavar="M",
                        help="place the traces by their marks, one every M metres along x (the file's marks: GSSI "
                             "DZT; or --marks)")
        sp.add_argument("--marks", default=None, metavar="TRACES",
                        help="the marked traces, e.g. 0,210,415 (with --marks-every; default the file's marks)")

    def add_track(sp):
        sp.add_argument("--track", default=None,
                        help="place the traces on a surveyed track: x y z text, CSV (x,y,z columns) or GSSI .DZG "
                             "(GPS fixes by trace)")
        add_marks(sp)

    def add_input(sp):
        sp.add_argument("input", help="radar file (DZT, DT1/HD, RD3/RAD, gprMax .h5/.out, gpr3d .h5)")
        sp.add_argument("--channel", type=int, default=0, help="channel of a multi-channel file (default 0)")
        sp.add_argument("--format", default=None, help="force a reader: dzt, dt1, rd3, gprmax, gpr3d")

    sp = add("info", cmd_info, "print what radar files hold",
             "example:\n  gpr3d info FILE____032.DZT XLINE00.DT1 --json")
    sp.add_argument("files", nargs="+", help="radar files")
    sp.add_argument("--format", default=None, help="force a reader")
    sp.add_argument("--json", action="store_true", help="print JSON instead of text")

    sp = add("show", cmd_show, "draw a B-scan as PNG",
             lambda: "example:\n  gpr3d show FILE____032.DZT --out b.png --steps time_zero dewow --axis depth --cmap hot"
             "\n\n" + _steps_help())
    add_input(sp)
    add_track(sp)
    sp.add_argument("--out", required=True, help="PNG file to write")
    sp.add_argument("--axis", choices=("time", "depth"), default="time", help="vertical axis (default time)")
    sp.add_argument("--eps-r", type=float, default=None, help="eps_r for the depth axis (default: file header)")
    sp.add_argument("--cmap", default="gray", help="colour map: gray, hot (as the reference paper), seismic, ...")
    sp.add_argument("--clip", type=float, default=99.0, help="colour limit percentile of |amplitude| (default 99)")
    sp.add_argument("--steps", nargs="*", default=[], help="processing before drawing")
    sp.add_argument("--style", choices=("image", "wiggle"), default="image",
                    help="image (default) or wiggle traces (at most 60, evenly spread)")
    sp.add_argument("--ascan", type=int, default=None, metavar="TRACE", help="draw this one trace (an A-scan) instead")
    sp.add_argument("--envelope", action="store_true",
                    help="draw the envelope (instantaneous amplitude) instead of the signed amplitude")

    sp = add("migrate", cmd_migrate, "migrate one profile in 2D (Kirchhoff, back projection, Stolt or RTM)",
             "examples:\n  gpr3d migrate XLINE00.DT1 --eps-r 9 --steps time_zero dewow remove_background --out mig\n"
             "  gpr3d migrate line.DZT --velocity 0.1 --method stolt --trace-spacing 0.02 --out mig")
    add_input(sp)
    add_track(sp)
    sp.add_argument("--out", required=True, help="output folder (profile.h5, profile.png)")
    sp.add_argument("--method", default="kirchhoff", choices=("kirchhoff", "backprojection", "stolt", "rtm"),
                    help="kirchhoff (default: obliquity weight, 50 deg aperture), backprojection (no weights), "
                         "stolt (f-k, zero offset), rtm (2D Maxwell reverse time)")
    sp.add_argument("--eps-r", default=None, help="relative permittivity of the host, or 'file' (the header's)")
    sp.add_argument("--velocity", type=float, default=None, help="wave speed in m/ns (instead of --eps-r)")
    sp.add_argument("--max-depth", type=float, default=None, help="deepest depth (m; default: the record's reach)")
    sp.add_argument("--spacing", type=float, default=None, help="image cell along the line (m; default trace step)")
    sp.add_argument("--trace-spacing", type=float, default=None, help="trace spacing (m; default: the positions)")
    sp.add_argument("--air-gap", type=float, default=0.0,
                    help="the antenna's height above the ground (m; kirchhoff and backprojection; default 0)")
    sp.add_argument("--steps", nargs="*", default=[], metavar="STEP", help="processing first")

    sp = add("process", cmd_process, "process a radar file and write the result",
             lambda: "example:\n  gpr3d process FILE____032.DZT --steps time_zero dewow remove_background "
             "gain_tpow:power=1.5 --out p.h5\n\n" + _steps_help())
    add_input(sp)
    add_track(sp)
    sp.add_argument("--steps", nargs="+", required=True, help="processing steps in order")
    sp.add_argument("--out", required=True, help="output: .h5 (gpr3d), .sgy/.segy (SEG-Y) or .png")

    sp = add("convert", cmd_convert, "convert a radar file to gpr3d HDF5, SEG-Y or PNG",
             "example:\n  gpr3d convert XLINE00.DT1 xline00.sgy")
    add_input(sp)
    add_track(sp)
    sp.add_argument("out", help="output: .h5 (gpr3d), .sgy/.segy (SEG-Y) or .png")

    sp = add("grid", cmd_grid, "put parallel line files together into one survey with positions",
             "examples:\n  gpr3d grid XLINE*.DT1 --spacing 0.2 --out grid.h5\n"
             "  gpr3d grid L*.DZT --spacing 0.5 --serpentine --direction y --out grid.h5\n"
             "  gpr3d grid X*.DT1 --spacing 0.5 --cross Y*.DT1 --cross-spacing 0.5 --out grid.h5   (two sets)\n"
             "  gpr3d grid L*.DZT --layout lines.txt --out grid.h5     (lines.txt: NAME x0 y0 x1 y1 per line)")
    sp.add_argument("lines", nargs="+", help="line files, in the order they were recorded")
    sp.add_argument("--out", required=True, help="output survey (.h5)")
    sp.add_argument("--spacing", type=float, default=None, help="distance between neighbouring lines (m)")
    sp.add_argument("--direction", default="x", choices=("x", "y"), help="the lines run along x (default) or y")
    sp.add_argument("--serpentine", action="store_true", help="every second line was walked back (zig-zag)")
    sp.add_argument("--reversed", default="", help="lines walked back, as indices: 1,3,7")
    sp.add_argument("--start-offsets", default="", help="each line's start along its direction (m): 0,0.1,...")
    add_marks(sp)
    sp.add_argument("--cross", nargs="+", default=None, metavar="LINE",
                    help="a second set of lines, perpendicular to the first, in the order recorded")
    sp.add_argument("--cross-spacing", type=float, default=None,
                    help="distance between neighbouring cross lines (m; default --spacing)")
    sp.add_argument("--cross-origin", type=float, default=None,
                    help="where the first cross line lies along the first set's direction (m; default 0)")
    sp.add_argument("--layout", default=None, help="file of NAME x0 y0 x1 y1 lines (instead of --spacing)")
    sp.add_argument("--steps", nargs="*", default=[], metavar="STEP", help="processing steps for every line first")

    sp = add("cscan", cmd_cscan, "C-scans: time or depth slices of the envelope, gridded on the ground",
             "example:\n  gpr3d cscan grid.h5 --steps time_zero dewow remove_background --window-ns 10 --cell 0.05 "
             "--eps-r 9 --out cscan")
    add_input(sp)
    add_track(sp)
    sp.add_argument("--out", required=True, help="output folder (cscan.h5, cscan.png)")
    sp.add_argument("--cell", type=float, default=0.05, help="cell size (m; default 0.05)")
    sp.add_argument("--window-ns", type=float, default=10.0, help="slice thickness in two-way time (ns; default 10)")
    sp.add_argument("--eps-r", default=None, help="relative permittivity: label the slices with depths")
    sp.add_argument("--fill", type=float, default=None, help="fill empty cells within this distance (m; 2 cells)")
    sp.add_argument("--steps", nargs="*", default=[], metavar="STEP", help="processing steps first")

    sp = add("simulate", cmd_simulate, "build a labelled dataset of simulated B-scans (resumable)",
             "examples:\n  gpr3d simulate --engine gprmax --n 1 --seed 0 --out sim1\n"
             "  gpr3d simulate --n 400 --workers 2 --out gprmax400         (re-run to resume)\n"
             "  gpr3d simulate --n 5000 --scheduler tcp://10.0.0.5:8786 --out big\n"
             "  gpr3d simulate --preset survey --seed 4242 --n 180 --workers 1 --out gprmax_survey   "
             "(held-out set)")
    sp.add_argument("--out", required=True, help="dataset folder (re-running with the same settings resumes)")
    sp.add_argument("--n", type=int, required=True, help="number of samples (scene indices 0..n-1)")
    sp.add_argument("--seed", type=int, default=0, help="master seed: scene i is sample_scene(seed, i)")
    sp.add_argument("--engine", choices=("gprmax", "forward"), default="gprmax", help="simulator (default gprmax)")
    sp.add_argument("--workers", type=int, default=2, help="local Dask worker processes (default 2)")
    sp.add_argument("--scheduler", default=None, help="tcp://HOST:PORT of a Dask scheduler to run on instead")
    sp.add_argument("--preset", choices=("standard", "tiny", "survey"), default="standard",
                    help="scene sizes: standard (the sampler's ranges), tiny (seconds each, for smoke tests) or "
                         "survey (survey-scale scans of the held-out gprMax set, 100-200 traces each)")
    sp.add_argument("--host", choices=("concrete", "soil"), default=None, help="only this host medium")
    sp.add_argument("--image-height", type=int, default=256, help="rows of the detector images (default 256)")
    sp.add_argument("--start", type=int, default=0,
                    help="first scene index (build start..n-1; e.g. to share one set between machines)")
    sp.add_argument("--max-seconds", type=float, default=None,
                    help="stop after this long, keeping every finished sample (re-run to resume)")
    sp.add_argument("--no-progress", action="store_true", help="no progress bar")

    sp = add("pose", cmd_pose, "antenna poses from an IMU, visual odometry and a survey wheel (error-state EKF)",
             "examples:\n  gpr3d pose simulate --out rig1                 (a synthetic cart's recordings and truth)\n"
             "  gpr3d pose fuse --imu rig1/imu.csv --odometry rig1/odometry.tum --wheel rig1/wheel.csv \\\n"
             "      --rig rig1/rig.json --still 2 --out antenna.tum --truth rig1/truth.tum --figure paths.png\n"
             "  gpr3d pose fuse --bag run.bag --colour-topic /camera/color/image_raw \\\n"
             "      --depth-topic /camera/aligned_depth_to_color/image_raw --rig rig.json --out antenna.tum\n"
             "IMU CSV: t,ax,ay,az,gx,gy,gz (s, m/s^2, rad/s); wheel CSV: t,distance (s, m); odometry: a TUM file "
             "of camera poses\n(a jump in its frame times is lost tracking); rig JSON: imu_T_camera, imu_T_antenna "
             "(4 x 4), camera_time_offset_s.")
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
    sp.add_argument("--truth", default=None, help="a true antenna trajectory to report the APE against (evo)")
    sp.add_argument("--figure", default=None, help="PNG plan view of the path")
    sp.add_argument("--duration", type=float, default=90.0, help="simulate: seconds of motion (90)")
    sp.add_argument("--seed", type=int, default=0, help="simulate: seed")

    sp = add("dataset", cmd_dataset, "pack a simulated dataset into one file, or export a packed one as COCO",
             "examples:\n  gpr3d dataset pack gprmax400 datasets/gprmax400.h5\n"
             "  gpr3d dataset export datasets/gprmax400.h5 coco_out\n"
             "  gpr3d dataset preview gprmax400 labels.png --index 0")
    sp.add_argument("action", choices=("pack", "export", "preview"),
                    help="pack: folder -> file; export: file -> images + COCO; preview: one sample's labels as PNG")
    sp.add_argument("src", help="dataset folder (pack, preview) or packed file (export, preview)")
    sp.add_argument("dst", help="packed file (pack), output folder (export) or PNG (preview)")
    sp.add_argument("--index", type=int, default=0, help="sample to preview")
    sp.add_argument("--n-samples", type=int, default=512, help="samples per trace in the packed file")
    sp.add_argument("--image-height", type=int, default=256, help="image rows (export)")
    sp.add_argument("--regenerate", default=None, help="the command that regenerates the dataset (stored)")

    sp = add("reconstruct", cmd_reconstruct, "3D migration from antenna poses and target extraction",
             "examples:\n  gpr3d reconstruct gpr3d_demo/random_walk_survey.h5 --out rec\n"
             "  gpr3d reconstruct LINE.DZT --poses LINE.tum --eps-r 9 --boxes detections.json --out rec\n\n"
             "outputs: volume.h5, volume.vti (ParaView), top.png, front.png, view3d.png, targets.json\n"
             "(targets: x, y, depth positive down, metres; endpoints for lines)")
    add_input(sp)
    add_track(sp)
    sp.add_argument("--out", required=True, help="output folder")
    sp.add_argument("--poses", default=None, help="TUM trajectory, one pose per trace in trace order")
    sp.add_argument("--eps-r", default=None,
                    help="relative permittivity, or 'file' for the header's (default: estimated from the data, "
                         "see --depth)")
    sp.add_argument("--boxes", default=None, help="JSON boxes (gpr3d detect output or a list): migrate only these")
    sp.add_argument("--method", default="backprojection", choices=("backprojection", "pseudo3d"),
                    help="backprojection (default: every trace into the 3D grid from its pose) or pseudo3d (a grid "
                         "survey's lines migrated one by one in 2D, interpolated between lines)")
    rc = _reconstruct_defaults()
    sp.add_argument("--spacing", type=float, default=rc.spacing_m, help=f"voxel size in metres (default {rc.spacing_m:g})")
    sp.add_argument("--max-depth", type=float, default=rc.max_depth_m, help="deepest voxel (m; default: the time window)")
    sp.add_argument("--aperture", type=float, default=rc.aperture_deg,
                    help=f"beam half-angle in degrees (0: none; default {rc.aperture_deg:g})")
    sp.add_argument("--threshold", type=float, default=rc.threshold,
                    help=f"target threshold, fraction of the image's 99.5th-percentile column maximum ({rc.threshold:g})")
    sp.add_argument("--min-line", type=float, default=rc.min_line_m, help=f"shortest line target (m; {rc.min_line_m:g})")
    sp.add_argument("--min-depth", type=float, default=rc.min_target_depth_m,
                    help="no targets shallower than this (m; e.g. where the direct wave rings)")
    sp.add_argument("--no-time-zero", action="store_true", help="the data already start at time zero")
    sp.add_argument("--air-gap", type=float, default=rc.air_gap_m,
                    help="the antennas' height above the ground (m) when held a wavelength or more above it (an "
                         f"air-launched antenna: the rays refract at the surface; default {rc.air_gap_m:g})")
    sp.add_argument("--engine", choices=("numba", "numpy"), default=rc.engine, help="migration kernel")
    sp.add_argument("--mask", choices=("none", "detect"), default="none",
                    help="detect: run the detector on the trace sequence and migrate only its boxes")
    sp.add_argument("--tile", type=float, default=rc.tile_m,
                    help="site scale: migrate in tiles of this side (m), each with only the traces that reach it "
                         "(default: the whole grid at once; 5 with --workers, --scheduler or --resume)")
    sp.add_argument("--workers", type=int, default=rc.workers,
                    help="site scale: local Dask worker processes for the tiles (default 0: this process)")
    sp.add_argument("--scheduler", default=rc.scheduler,
                    help="site scale: address of a running Dask scheduler (tcp://host:8786) for the tiles")
    sp.add_argument("--resume", action="store_true",
                    help="keep finished tiles in OUT/tiles/ and reuse them when the same command runs again")
    add_detector_args(sp)
    add_depth_args(sp, "--depth")

    sp = add("detect", cmd_detect, "find hyperbolas in a radar file (boxes, scores, apexes as JSON)",
             "examples:\n  gpr3d detect FILE____032.DZT --out det.json --overlay det.png\n"
             "  gpr3d detect line.h5 --out det.json --weights my_detector.pt --score 0.3\n"
             "  gpr3d detect bscan.png --pixel-map s_per_px=3.125e-11 --frequency 1.6e9 --out det.json\n\n"
             "output: {input, n_traces, dt_s, targets: [{box: [trace_start, t_start_s, trace_end, t_end_s], score,\n"
             "apex_trace, apex_time_s, kind, kind_score}]}; times from the first recorded sample; a list for\n"
             "multi-channel files")
    sp.add_argument("input", help="radar file (DZT, DT1/HD, RD3/RAD, gprMax .h5/.out, gpr3d .h5) or a picture of a "
                                  "B-scan (PNG, JPG, ...: give --pixel-map)")
    sp.add_argument("--format", default=None, help="force a reader: dzt, dt1, rd3, gprmax, gpr3d")
    sp.add_argument("--pixel-map", default=None,
                    help="a picture's time axis: s_per_px=SECONDS[,t0_s=..] (one trace per column)")
    sp.add_argument("--frequency", type=float, default=None, metavar="HZ",
                    help="a picture's antenna frequency (apex times, depths)")
    sp.add_argument("--out", required=True, help="JSON file to write")
    sp.add_argument("--overlay", default=None, help="PNG of the B-scan with the boxes drawn (first channel)")
    add_detector_args(sp)
    add_depth_args(sp, "--depth")

    sp = add("depth", cmd_depth, "host permittivity and the depth of every detected target (table)",
             "examples:\n  gpr3d depth FILE____032.DZT\n  gpr3d depth line.h5 --boxes det.json --method fit "
             "--trace-spacing 0.01\n\ndepth: to the top of the target below the surface (m); x: along the profile")
    add_input(sp)
    sp.add_argument("--boxes", default=None, help="detections (gpr3d detect output) instead of running the detector")
    sp.add_argument("--out", default=None, help="also write the detections with depths as JSON")
    add_detector_args(sp)
    add_depth_args(sp, "--method")

    sp = add("train", cmd_train, "train the hyperbola detector or DepthNet on survey-scale B-scans (resumable)",
             "examples:\n  gpr3d train detector --out det_run --steps 3000 --batch 8          (CPU)\n"
             "  gpr3d train depthnet --out dn_run --packed datasets/gprmax400.h5 datasets/gprmax_survey_train.h5:0\n"
             "  gpr3d train detector --out det_run --steps 6000 --batch 16 --device cuda --workers 12\n"
             "  gpr3d train detector --init default --labels my_bscans/coco.json --steps 300 --out ft   "
             "(fine-tune on your labels)\n"
             "re-run the same command to resume after a kill; weights go to OUT/weights.pt")
    sp.add_argument("what", choices=("detector", "depthnet"), help="what to train")
    sp.add_argument("--out", required=True, help="run folder (checkpoint.pt, losses.csv, weights.pt)")
    sp.add_argument("--model", default="frcnn_lean", help="frcnn_lean (default), frcnn_r18/r50/r101, "
                    "frcnn_mobilenet, retinanet_r18, fcos_r18, ssdlite")
    sp.add_argument("--steps", type=int, default=None, help="optimiser steps (default 3000; depthnet 2000)")
    sp.add_argument("--batch", type=int, default=None, help="windows per step (default 8; depthnet 16)")
    sp.add_argument("--arch", default="resnet10n",
                    help="depthnet encoder: resnet10n (default, trains on CPU), resnet18/34/50/101 (the reference)")
    sp.add_argument("--width", type=int, default=24, help="depthnet: first-stage channels of resnet10n (24)")
    sp.add_argument("--records", type=int, default=1500,
                    help="depthnet: forward-model records to train on (prepared once into OUT; default 1500)")
    sp.add_argument("--lr", type=float, default=None, help="learning rate (default: the optimiser's)")
    sp.add_argument("--optimiser", default="adamw",
                    help="adamw (default), sgd (detector), reference (the paper's SGD: lr 4e-5, momentum 0.9)")
    sp.add_argument("--warmup", type=int, default=200, help="steps of linear learning-rate warm-up (default 200)")
    sp.add_argument("--seed", type=int, default=0, help="initialisation seed")
    sp.add_argument("--data-seed", type=int, default=None,
                    help="synthetic records survey_sample(SEED, i) (default 1000; depthnet 2000)")
    sp.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:N")
    sp.add_argument("--workers", type=int, default=0, help="data-loading processes (default 0)")
    sp.add_argument("--checkpoint-every", type=int, default=100, help="steps between checkpoints")
    sp.add_argument("--max-seconds", type=float, default=None, help="stop after this long (resume later)")
    sp.add_argument("--init", default=None, help="start from these weights (fine-tuning); 'default': the shipped ones")
    sp.add_argument("--labels", default=None,
                    help="your own labelled B-scans mixed in: a YOLO dataset (data.yaml, or a folder with images/ "
                         "and labels/), COCO .json, Pascal VOC .xml or a folder of them (images may be radar files "
                         "or pictures; see docs/CONVENTIONS.md)")
    sp.add_argument("--labels-fraction", type=float, default=0.5, help="share of windows from --labels (0.5)")
    add_label_args(sp)
    sp.add_argument("--kinds", default=None, metavar="K,K",
                    help="target kinds the detector tells apart, e.g. rebar,steel_pipe,pvc_pipe,void,tank "
                         "(default: those of --init; a one-class --init is widened to them)")
    sp.add_argument("--freeze", type=int, default=0,
                    help="backbone stages kept fixed: 1 the stem, 2 with layer1 (faster CPU fine-tuning; default 0)")
    sp.add_argument("--packed", nargs="+", default=None,
                    help="mix records of packed datasets in, each FILE or FILE:N (its last N held out; default "
                         "--packed-holdout), e.g. datasets/gprmax400.h5 datasets/gprmax_survey_train.h5:0")
    sp.add_argument("--packed-fraction", type=float, default=0.2, help="share of windows from --packed (0.2)")
    sp.add_argument("--packed-holdout", type=int, default=60, help="last records of --packed kept out (60)")
    sp.add_argument("--no-progress", action="store_true", help="no progress bar")

    sp = add("eval", cmd_eval, "evaluate the detector (COCO metrics) or the depth estimates on held-out B-scans",
             "examples:\n  gpr3d eval detector --n 60 --seed 777\n  gpr3d eval detector --data datasets/gprmax_survey.h5\n"
             "  gpr3d eval depth --data datasets/gprmax_survey.h5      (DepthNet, fit and hybrid)\n"
             "the full tables: python benchmarks/eval_detector.py WEIGHTS.pt ...; python benchmarks/eval_depth.py")
    sp.add_argument("what", choices=("detector", "depth"), help="what to evaluate")
    sp.add_argument("--depthnet", default=None, help="depth: DepthNet weights (default: the shipped ones)")
    sp.add_argument("--n", type=int, default=None, help="records (default: 60 drawn, or all of --data)")
    sp.add_argument("--seed", type=int, default=777, help="seed of the held-out set (training uses 1000)")
    sp.add_argument("--data", default=None,
                    help="evaluate on a labelled dataset instead: packed file or gpr3d simulate folder "
                         "(e.g. datasets/gprmax_survey.h5)")
    sp.add_argument("--labels", default=None,
                    help="evaluate on labelled B-scans: a YOLO dataset, COCO .json or Pascal VOC .xml "
                         "(e.g. pgpr_1600MHz/val with --pixel-map s_per_px=3.125e-11 --class-names steel,pipe "
                         "--class-kinds pipe=pvc_pipe)")
    sp.add_argument("--split", default="val", choices=("train", "val", "test"),
                    help="the split of a YOLO data.yaml to evaluate on (default val)")
    add_label_args(sp)
    add_detector_args(sp)

    sp = add("demo", cmd_demo, "run the end-to-end demo (embedded example by default)",
             "example:\n  gpr3d demo --out gpr3d_demo")
    sp.add_argument("--out", default="gpr3d_demo", help="output folder (default gpr3d_demo)")
    sp.add_argument("--input", default=None, help="use this radar file instead of the embedded example")
    return p


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"gpr3d: warning: {message}", file=sys.stderr)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    warnings.showwarning = _one_line_warning
    try:
        if hasattr(args, "marks_every"):
            _check_marks_args(args)  # before any file is read
        return int(args.func(args) or 0)
    except GPR3DError as exc:
        print(f"gpr3d: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # e.g. an unwritable output folder
        print(f"gpr3d: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 1
    except MemoryError:
        print(f"gpr3d: error: {args.command}: out of memory (the input, or the grid asked for, is larger than this "
              "machine's memory)", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("gpr3d: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
