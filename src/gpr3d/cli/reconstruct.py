"""``gpr3d reconstruct``: 3D migration from antenna poses and target extraction."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gpr3d.cli._common import (
    _check_radius,
    _eps_argument,
    _in_range,
    _migration_engine,
    _out_folder,
    _reconstruct_defaults,
    add_depth_args,
    add_detector_args,
    add_input,
    add_track,
)
from gpr3d.core.errors import GPR3DError

#: ReconstructConfig's names for the settings that reconstruct's options set
_RECONSTRUCT_FLAGS = {"spacing_m": "--spacing", "max_depth_m": "--max-depth", "aperture_deg": "--aperture",
                      "threshold": "--threshold", "min_line_m": "--min-line", "engine": "--engine",
                      "min_target_depth_m": "--min-depth", "method": "--method", "tile_m": "--tile",
                      "air_gap_m": "--air-gap", "refine_level": "--refine-level", "aperture_m": "--aperture-radius"}


NAME = "reconstruct"
HELP = "3D migration from antenna poses and target extraction"
EPILOG = ("examples:\n  gpr3d reconstruct gpr3d_demo/random_walk_survey.h5 --out rec\n"
             "  gpr3d reconstruct LINE.DZT --poses LINE.tum --eps-r 9 --boxes detections.json --out rec\n\n"
             "outputs: volume.h5, volume.vti (ParaView), top.png, front.png, view3d.png, targets.json\n"
             "(targets: x, y, depth positive down, metres; endpoints for lines)")


def add_arguments(sp):
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
    sp.add_argument("--spacing", type=float, default=rc.spacing_m,
                    help="voxel size in metres (default: a tenth of the antenna's centre wavelength in the ground, to "
                         "the millimetre, 2 cm or more; 2 cm where the file names no frequency)")
    sp.add_argument("--max-depth", type=float, default=rc.max_depth_m,
                    help="deepest voxel (m; default: what the time window reaches)")
    sp.add_argument("--signal-depth", action="store_true",
                    help="end the grid where the signal ends: where neighbouring traces stop looking alike, the "
                         "noise alone left (config.json's 'depth' says where and why; for records much deeper "
                         "than their signal)")
    sp.add_argument("--aperture", type=float, default=rc.aperture_deg,
                    help=f"beam half-angle in degrees (0: none; default {rc.aperture_deg:g})")
    sp.add_argument("--aperture-radius", type=float, default=rc.aperture_m,
                    help="the aperture's horizontal radius (m): a trace adds only to the columns within it of its "
                         "antennas' midpoint, at any depth, the cone still applying where it is narrower (0: none; "
                         f"default {'none' if rc.aperture_m is None else format(rc.aperture_m, 'g')}; faster on deep "
                         "grids, benchmarks/results/aperture_radius.md)")
    sp.add_argument("--threshold", type=float, default=rc.threshold,
                    help=f"target threshold, fraction of the image's 99.5th-percentile column maximum ({rc.threshold:g})")
    sp.add_argument("--min-line", type=float, default=rc.min_line_m, help=f"shortest line target (m; {rc.min_line_m:g})")
    sp.add_argument("--min-depth", type=float, default=rc.min_target_depth_m,
                    help="no targets shallower than this (m; e.g. where the direct wave rings)")
    sp.add_argument("--no-time-zero", action="store_true", help="the data already start at time zero")
    sp.add_argument("--air-gap", type=float, default=rc.air_gap_m,
                    help="the antennas' height above the ground (m) when held a wavelength or more above it (an "
                         f"air-launched antenna: the rays refract at the surface; default {rc.air_gap_m:g})")
    sp.add_argument("--coarse-to-fine", action=argparse.BooleanOptionalAction, default=rc.coarse_to_fine,
                    help="a coarse pass over every few columns first, then every voxel of the depths where it "
                         "finds energy, the others interpolated (config.json's 'refine' says how many; default "
                         f"{'on' if rc.coarse_to_fine else 'off'}); --no-coarse-to-fine: every voxel migrated")
    sp.add_argument("--refine-level", type=float, default=None,
                    help="coarse-to-fine: refine where the coarse envelope reaches this share of "
                         f"--threshold (default {rc.refine_level:g})")
    sp.add_argument("--engine", choices=("numba", "numpy", "torch"), default=None,
                    help=f"migration kernel (default {rc.engine}; torch with --device cuda: the GPU)")
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


def run(args):
    from gpr3d.migration.reconstruct import ReconstructConfig, check_config
    from gpr3d.migration.targets import target_name
    from gpr3d.pipeline import (
        attach_trajectory,
        load_models,
        read_recording,
        reconstruct_recording,
        write_reconstruction_folder,
    )
    from gpr3d.viz.worker import FigureWorker

    if args.mask == "detect" and args.boxes:
        raise GPR3DError("give --boxes or --mask detect, not both")
    _out_folder(args.out, "reconstruct")
    site = dict(tile_m=args.tile, workers=args.workers, scheduler=args.scheduler,
                checkpoint=str(Path(args.out) / "tiles") if args.resume else None)
    if args.aperture < 0:
        raise GPR3DError(f"--aperture must be 0 (none) or a cone half-angle in (0, 90) degrees, got {args.aperture:g}")
    if args.tile is not None and args.spacing is None:
        # (the data's voxel is known once the file is read: reconstruct checks the tile against it then)
        from gpr3d.migration.reconstruct import SPACING_RANGE_M

        _in_range(args.tile, "--tile", 10 * SPACING_RANGE_M[0], 1e5,
                  f"a tile side in metres, at least 10 voxels (the data's voxels are {SPACING_RANGE_M[0]:g} m or more)")
    elif args.tile is not None and args.spacing > 0 and math.isfinite(args.spacing):
        # a tile of a few voxels spends its time on its margins (0.0001 m once ran 41,000 one-voxel tiles)
        _in_range(args.tile, "--tile", 10 * args.spacing, 1e5, f"a tile side in metres, at least 10 voxels of "
                                                                f"--spacing {args.spacing:g}")
    if args.signal_depth and args.max_depth is not None:
        raise GPR3DError("give --max-depth or --signal-depth, not both")
    if args.refine_level is not None and not args.coarse_to_fine:
        raise GPR3DError("--refine-level sets how coarse-to-fine imaging refines: leave --no-coarse-to-fine out")
    engine = _migration_engine(args.engine, args.device)
    settings = dict(spacing_m=args.spacing, max_depth_m=args.max_depth,
                    aperture_deg=None if args.aperture == 0 else args.aperture,
                    aperture_m=args.aperture_radius or None, threshold=args.threshold,
                    min_line_m=args.min_line, engine=engine, time_zero="none" if args.no_time_zero else "peak",
                    min_target_depth_m=args.min_depth, method=args.method, air_gap_m=args.air_gap,
                    coarse_to_fine=args.coarse_to_fine, signal_depth=args.signal_depth,
                    refine_level=ReconstructConfig.refine_level if args.refine_level is None else args.refine_level)
    check_config(ReconstructConfig(**settings, **site), names=_RECONSTRUCT_FLAGS)  # one line, before any work
    eps_given = _eps_argument(args.eps_r)
    estimate = eps_given is None
    if args.radius is not None and not estimate:
        raise GPR3DError("--radius is used to estimate eps_r: leave --eps-r out, or leave --radius out")
    _check_radius(args, args.depth)
    if not 0.0 <= args.score <= 1.0:
        raise GPR3DError(f"--score must lie in 0..1, got {args.score}")
    # the figures' process forked first, before any thread starts (it imports matplotlib while the file is read)
    with FigureWorker() as figures:
        # weights checked before the work starts
        detector, depthnet = load_models(detector=args.mask == "detect" or (estimate and not args.boxes),
                                         depth=args.depth if estimate else "none", weights=args.weights,
                                         depthnet=args.depthnet, device=args.device, runtime=args.runtime,
                                         refiner=args.refiner)
        if engine == "numba" and args.method == "backprojection" and (args.aperture or args.aperture_radius):
            from gpr3d.migration import preload_tiled

            preload_tiled()  # the tiled kernel loaded while the file is read (the migration waits for it)
        survey = read_recording(args.input, format=args.format, channel=args.channel, track=args.track,
                                marks_every_m=args.marks_every, marks=args.marks)
        if args.poses:
            survey = attach_trajectory(survey, args.poses, source=str(args.input))
        done = reconstruct_recording(survey, ReconstructConfig(**settings, **site), eps_r=eps_given,
                                     boxes_file=args.boxes, mask=args.mask, detector=detector, depthnet=depthnet,
                                     depth=args.depth, trace_spacing_m=args.trace_spacing, radius_m=args.radius,
                                     score=args.score, input_name=str(args.input), log=print)
        files = write_reconstruction_folder(done, args.out, source=str(args.input), figures=figures)
    result = done.result
    g = result.grid
    ref = result.refine or {}
    coarse = "why" not in ref and ref.get("refined_fraction", 1.0) < 1.0  # coarse-to-fine refined part of the voxels
    every = " counted over every voxel" if coarse else ""
    rate = f" ({result.updates_per_s / 1e9:.2f} G voxel-trace updates/s{every})" if result.updates_per_s else ""
    how = "line by line (pseudo-3D)" if args.method == "pseudo3d" else "onto"
    print(f"migrated {result.n_traces} traces {how} {g.nx} x {g.ny} x {g.nd} voxels in "
          f"{result.timings_s['migrate']:.1f} s{rate}")
    if coarse:
        print(f"coarse-to-fine: every {ref['stride']} columns at every depth, then {ref['refined_fraction']:.0%} of "
              "the voxels at full resolution where that image holds energy, the rest interpolated "
              "(--no-coarse-to-fine: every voxel)")
    elif "skipped" in ref:
        print(f"coarse-to-fine left out: {ref['skipped']}")
    elif "why" in ref:
        print(f"coarse-to-fine: {ref['why']}")
    if result.frame is not None:
        print("one straight profile: migrated in 2D (the vertical plane under it); targets crossing it are points")
    for i, t in enumerate(result.targets):
        pts = "  ".join("(" + ", ".join(f"{v:.2f}" for v in p) + ")" for p in t.points_xyz)
        print(f"  {target_name(i):>4} {t.kind:5s} depth {t.depth_m:.2f} m  score {t.score:.2f}  {pts}")
    print(f"wrote {', '.join(files)} to {args.out}/")
    return 0

