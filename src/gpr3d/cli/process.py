"""``gpr3d process``: process a radar file and write the result."""

from __future__ import annotations

from gpr3d.cli._common import _check_suffix, _read_channel, _steps_help, add_input, add_track
from gpr3d.pipeline import SURVEY_SUFFIXES, apply_steps, write_survey

NAME = "process"
HELP = "process a radar file and write the result"
EPILOG = (lambda: "example:\n  gpr3d process FILE____032.DZT --steps time_zero dewow remove_background "
             "gain_tpow:power=1.5 --out p.h5\n\n" + _steps_help())


def add_arguments(sp):
    add_input(sp)
    add_track(sp)
    sp.add_argument("--steps", nargs="+", required=True, help="processing steps in order")
    sp.add_argument("--out", required=True, help="output: .h5 (gpr3d), .sgy/.segy (SEG-Y) or .png")


def run(args):
    _check_suffix(args.out, SURVEY_SUFFIXES, "--out")  # before the work
    s = apply_steps(_read_channel(args), args.steps)
    write_survey(s, args.out)
    print(f"wrote {args.out}: {s}")
    return 0
