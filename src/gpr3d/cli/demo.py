"""``gpr3d demo``: run the end-to-end demo (embedded example by default)."""

from __future__ import annotations

NAME = "demo"
HELP = "run the end-to-end demo (embedded example by default)"
EPILOG = "example:\n  gpr3d demo --out gpr3d_demo"


def add_arguments(sp):
    sp.add_argument("--out", default="gpr3d_demo", help="output folder (default gpr3d_demo)")
    sp.add_argument("--input", default=None, help="use this radar file instead of the embedded example")


def run(args):
    from gpr3d.demo import DemoConfig, run_demo

    run_demo(args.out, DemoConfig(input=args.input))
    return 0
