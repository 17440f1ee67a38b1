"""``gpr3d migrate``: migrate one profile in 2D (Kirchhoff, back projection, Stolt or RTM)."""

from __future__ import annotations

import math
from pathlib import Path

from gpr3d.cli._common import _eps_argument, _out_folder, _read_channel, add_input, add_track
from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import apply_steps

NAME = "migrate"
HELP = "migrate one profile in 2D (Kirchhoff, back projection, Stolt or RTM)"
EPILOG = ("examples:\n  gpr3d migrate XLINE00.DT1 --eps-r 9 --steps time_zero dewow remove_background --out mig\n"
             "  gpr3d migrate line.DZT --velocity 0.1 --method stolt --trace-spacing 0.02 --out mig")


def add_arguments(sp):
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


def run(args):
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
    s = apply_steps(_read_channel(args), args.steps)
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
