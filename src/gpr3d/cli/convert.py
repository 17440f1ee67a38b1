"""``gpr3d convert``: convert a radar file to gpr3d HDF5, SEG-Y or PNG."""

from __future__ import annotations

from gpr3d.cli._common import _check_suffix, _read_channel, add_input, add_track
from gpr3d.pipeline import SURVEY_SUFFIXES, write_survey

NAME = "convert"
HELP = "convert a radar file to gpr3d HDF5, SEG-Y or PNG"
EPILOG = "example:\n  gpr3d convert XLINE00.DT1 xline00.sgy"


def add_arguments(sp):
    add_input(sp)
    add_track(sp)
    sp.add_argument("out", help="output: .h5 (gpr3d), .sgy/.segy (SEG-Y) or .png")


def run(args):
    _check_suffix(args.out, SURVEY_SUFFIXES, "output")
    s = _read_channel(args)
    write_survey(s, args.out)
    print(f"wrote {args.out}: {s}")
    return 0
