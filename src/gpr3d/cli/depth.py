"""``gpr3d depth``: host permittivity and the depth of every detected target (table)."""

from __future__ import annotations

from gpr3d.cli._common import (_check_radius, _check_suffix, _detector, add_depth_args, add_detector_args, add_input,
                               add_view_args)
from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import add_depths, load_models, read_targets

NAME = "depth"
HELP = "host permittivity and the depth of every detected target (table)"
EPILOG = ("examples:\n  gpr3d depth FILE____032.DZT\n  gpr3d depth line.h5 --boxes det.json --method fit "
             "--trace-spacing 0.01\n\ndepth: to the top of the target below the surface (m); x: along the profile")


def add_arguments(sp):
    add_input(sp)
    sp.add_argument("--boxes", default=None, help="detections (gpr3d detect output) instead of running the detector")
    sp.add_argument("--out", default=None, help="also write the detections with depths as JSON")
    add_detector_args(sp)
    add_view_args(sp)
    add_depth_args(sp, "--method")


def run(args):
    from gpr3d.io.registry import read

    if args.trace_spacing is not None and not args.trace_spacing > 0:
        raise GPR3DError(f"--trace-spacing must be a positive number of metres, got {args.trace_spacing}")
    _check_suffix(args.out, (".json",), "--out")
    _check_radius(args, args.method)
    det = _detector(args) if not args.boxes else None
    depthnet = load_models(detector=False, depth=args.method, depthnet=args.depthnet, device=args.device)[1]
    survey = read(args.input, format=args.format, channel=args.channel)
    if args.boxes:
        found = read_targets(args.boxes, survey, channel=args.channel, input_name=args.input)
    else:
        found = det.detect(survey, score_threshold=args.score, input_name=str(args.input))
    if survey.distances_m is None and args.trace_spacing is None:
        raise GPR3DError(f"{args.input}: the file has no trace positions; give --trace-spacing (m)")
    add_depths(survey, found, args.method, depthnet, args.trace_spacing, args.radius)
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
