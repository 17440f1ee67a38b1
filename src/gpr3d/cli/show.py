"""``gpr3d show``: draw a B-scan as PNG."""

from __future__ import annotations

from pathlib import Path

from gpr3d.cli._common import _check_suffix, _read_channel, _steps_help, add_input, add_track
from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import apply_steps

NAME = "show"
HELP = "draw a B-scan as PNG"
EPILOG = (lambda: "example:\n  gpr3d show FILE____032.DZT --out b.png --steps time_zero dewow --axis depth --cmap hot"
             "\n\n" + _steps_help())


def add_arguments(sp):
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


def run(args):
    from gpr3d.viz.bscan import check_plot_args, save_bscan_png

    _check_suffix(args.out, (".png",), "--out")
    for flag, kw in (("--cmap", {"cmap": args.cmap}), ("--clip", {"clip_percentile": args.clip})):
        try:
            check_plot_args(**kw)
        except GPR3DError as exc:
            raise GPR3DError(f"{flag}: {exc}") from None
    s = apply_steps(_read_channel(args), args.steps)
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
