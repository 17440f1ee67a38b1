"""``gpr3d cscan``: C-scans: time or depth slices of the envelope, gridded on the ground."""

from __future__ import annotations

from pathlib import Path

from gpr3d.cli._common import _eps_argument, _in_range, _out_folder, _read_channel, add_input, add_track
from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import apply_steps

NAME = "cscan"
HELP = "C-scans: time or depth slices of the envelope, gridded on the ground"
EPILOG = ("example:\n  gpr3d cscan grid.h5 --steps time_zero dewow remove_background --window-ns 10 --cell 0.05 "
             "--eps-r 9 --out cscan")


def add_arguments(sp):
    add_input(sp)
    add_track(sp)
    sp.add_argument("--out", required=True, help="output folder (cscan.h5, cscan.png)")
    sp.add_argument("--cell", type=float, default=0.05, help="cell size (m; default 0.05)")
    sp.add_argument("--window-ns", type=float, default=10.0, help="slice thickness in two-way time (ns; default 10)")
    sp.add_argument("--eps-r", default=None, help="relative permittivity: label the slices with depths")
    sp.add_argument("--fill", type=float, default=None, help="fill empty cells within this distance (m; 2 cells)")
    sp.add_argument("--steps", nargs="*", default=[], metavar="STEP", help="processing steps first")


def run(args):
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
    s = apply_steps(_read_channel(args), args.steps)
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
