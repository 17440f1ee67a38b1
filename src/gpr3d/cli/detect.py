"""``gpr3d detect``: find hyperbolas in a radar file (boxes, scores, apexes as JSON)."""

from __future__ import annotations

from pathlib import Path

from gpr3d.cli._common import (_check_radius, _check_suffix, _detector, add_depth_args, add_detector_args,
                               add_view_args)
from gpr3d.core.errors import GPR3DError
from gpr3d.core.timing import stage
from gpr3d.pipeline import add_depths, load_models

NAME = "detect"
HELP = "find hyperbolas in a radar file (boxes, scores, apexes as JSON)"
EPILOG = ("examples:\n  gpr3d detect FILE____032.DZT --out det.json --overlay det.png\n"
             "  gpr3d detect line.h5 --out det.json --weights my_detector.pt --score 0.3\n"
             "  gpr3d detect bscan.png --pixel-map s_per_px=3.125e-11 --frequency 1.6e9 --out det.json\n\n"
             "output: {input, n_traces, dt_s, targets: [{box: [trace_start, t_start_s, trace_end, t_end_s], score,\n"
             "apex_trace, apex_time_s, kind, kind_score, kind_shares}]}; times from the first recorded sample; a list\n"
             "for multi-channel files")


def add_arguments(sp):
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
    add_view_args(sp)
    add_depth_args(sp, "--depth")


def run(args):
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
    with stage("load models"):
        det = _detector(args)  # weights checked before the recording is read
    depthnet = load_models(detector=False, depth=args.depth, depthnet=args.depthnet, device=args.device)[1]
    with stage("read"):
        surveys = [read_picture(args.input, args.pixel_map, frequency_hz=args.frequency)] if picture else \
            read_all(args.input, format=args.format)
    with stage("detect"):
        results = [det.detect(s, score_threshold=args.score, input_name=str(args.input)) for s in surveys]
    if args.depth != "none":
        with stage("depths"):
            for s, r in zip(surveys, results):
                add_depths(s, r, args.depth, depthnet, args.trace_spacing, args.radius)
    with stage("write"):
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

        with stage("figures"):
            shown = surveys[0].dewow().remove_background()
            found = results[0]["targets"]
            save_bscan_png(shown, args.overlay, cmap="gray", boxes=[t["box"] for t in found],
                           apexes=[(t["apex_trace"], t["apex_time_s"]) for t in found],
                           title=f"{Path(args.input).name}: {len(found)} detections (score >= {args.score})")
    print(f"wrote {args.out}" + (f" and {args.overlay}" if args.overlay else ""))
    return 0
