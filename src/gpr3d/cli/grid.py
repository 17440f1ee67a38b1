"""``gpr3d grid``: put parallel line files together into one survey with positions."""

from __future__ import annotations

import math
from pathlib import Path

from gpr3d.cli._common import _check_suffix, _number_list, add_marks
from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import apply_steps, place_traces

NAME = "grid"
HELP = "put parallel line files together into one survey with positions"
EPILOG = ("examples:\n  gpr3d grid XLINE*.DT1 --spacing 0.2 --out grid.h5\n"
             "  gpr3d grid L*.DZT --spacing 0.5 --serpentine --direction y --out grid.h5\n"
             "  gpr3d grid X*.DT1 --spacing 0.5 --cross Y*.DT1 --cross-spacing 0.5 --out grid.h5   (two sets)\n"
             "  gpr3d grid L*.DZT --layout lines.txt --out grid.h5     (lines.txt: NAME x0 y0 x1 y1 per line)")


def add_arguments(sp):
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


def run(args):
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
    surveys = [apply_steps(place_traces(read(f), marks_every_m=args.marks_every, marks=args.marks), args.steps) for f in files]
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
