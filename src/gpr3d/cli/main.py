"""The ``gpr3d`` command: the parser, put together from one module per command, and the error handling.

Each command's module (``gpr3d.cli.info``, ``gpr3d.cli.reconstruct``, ...) holds its ``NAME``, ``HELP`` and
``EPILOG``, ``add_arguments(parser)`` and ``run(args)``: it parses, calls the library (mostly ``gpr3d.pipeline``),
and prints. User errors (bad files, bad arguments, missing extras) print one line on stderr and exit with status 1.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from pathlib import Path

from gpr3d import __version__
from gpr3d.cli._common import _check_marks_args, _Parser
from gpr3d.core.errors import GPR3DError

#: the commands' modules, in the order ``gpr3d --help`` lists them
COMMANDS = ["info", "show", "migrate", "process", "convert", "grid", "cscan", "simulate", "pose", "dataset",
            "reconstruct", "detect", "depth", "run", "live", "replay", "train", "evaluate", "demo"]

EXAMPLES = """\
examples:
  gpr3d demo                                   run the end-to-end demo on the embedded recording
  gpr3d info LINE01.DZT XLINE00.DT1 ten_col.rd3
  gpr3d show LINE01.DZT --out line01.png --axis depth --cmap hot
  gpr3d process LINE01.DZT --steps time_zero dewow remove_background gain_tpow:power=1.5 \\
        bandpass:fmin_hz=2e8:fmax_hz=8e8 --out line01.h5
  gpr3d convert LINE01.DZT line01.sgy          (.h5 gpr3d HDF5, .sgy/.segy SEG-Y, .png figure)
  gpr3d detect LINE01.DZT --out det.json --overlay det.png
  gpr3d reconstruct survey.h5 --mask detect --out rec
  gpr3d live tcp://cart.local:5600 --out site --eps-r 9 --until-idle 10
  gpr3d pose fuse --imu imu.csv --odometry cam.tum --wheel wheel.csv --rig rig.json --out antenna.tum
"""


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="gpr3d",
        description="Find and reconstruct buried objects from ground-penetrating radar.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"gpr3d {__version__}")
    p.add_argument("--timings", metavar="FILE", default=None,
                   help="time the command's stages (read, poses, detect, migrate, compile, targets, figures, "
                        "writes, ...): a table on stderr and the seconds in FILE (JSON)")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        mod = importlib.import_module(f"gpr3d.cli.{name}")
        sp = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP, epilog=mod.EPILOG,
                            formatter_class=argparse.RawDescriptionHelpFormatter)
        sp.set_defaults(func=mod.run)
        mod.add_arguments(sp)
    return p


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"gpr3d: warning: {message}", file=sys.stderr)


def _timed(args, argv) -> int:
    """Run the command inside :func:`gpr3d.core.timing.collect`; write its stages to ``args.timings``."""
    import json

    from llvmlite import binding

    from gpr3d.core.atomic import atomic_write_text
    from gpr3d.core.timing import collect, format_table, process_age_s

    startup = process_age_s()
    with collect() as times:
        rc = int(args.func(args) or 0)
    rows = ([("start-up", startup)] if startup is not None else []) + times.rows()
    cpu = binding.get_host_cpu_name()  # (LLVM's name, as numba's; llvmlite comes with numba)
    doc = {"gpr3d": __version__, "command": ["gpr3d"] + list(sys.argv[1:] if argv is None else argv),
           "host_cpu": cpu, "startup_s": startup, **times.to_dict(), "counts": times.counts}
    atomic_write_text(args.timings, json.dumps(doc, indent=1))
    print(format_table(rows, title=f"gpr3d {args.command}: where the time went ({cpu})"), file=sys.stderr)
    return rc


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    warnings.showwarning = _one_line_warning
    try:
        if hasattr(args, "marks_every"):
            _check_marks_args(args)  # before any file is read
        if args.timings:  # its file checked before any work
            from gpr3d.cli._common import _writable

            if Path(args.timings).is_dir():
                raise GPR3DError(f"--timings {args.timings}: is a folder; give a file name (e.g. timings.json)")
            _writable(args.timings, "--timings")
        from gpr3d.cli._warm import start_background

        start_background(args.command)  # the numba kernels compiled beside the command, once per machine
        if args.timings:
            return _timed(args, argv)
        return int(args.func(args) or 0)
    except GPR3DError as exc:
        print(f"gpr3d: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # e.g. an unwritable output folder
        print(f"gpr3d: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 1
    except MemoryError:
        print(f"gpr3d: error: {args.command}: out of memory (the input, or the grid asked for, is larger than this "
              "machine's memory)", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("gpr3d: interrupted", file=sys.stderr)
        return 130


def leave(rc: int) -> None:
    """End the process with status ``rc``: at once (``os._exit``, after flushing the output) when nothing is left
    to finish, no thread but this one that is not a daemon and no ``multiprocessing`` child, so that the
    interpreter's teardown (numba's thread pool, every module's clean-up: about 0.3 s a command on a 2-core host,
    ``benchmarks/results/bench_stages.md``) is not waited for; otherwise, or with ``GPR3D_FAST_EXIT=0``, as
    usual. Every file gpr3d writes is complete (and renamed into place) before its command returns."""
    import os
    import threading

    sys.stdout.flush()
    sys.stderr.flush()
    busy = [t for t in threading.enumerate() if t is not threading.main_thread() and t.is_alive() and not t.daemon]
    mp = sys.modules.get("multiprocessing")
    if not busy and not (mp and mp.active_children()) and os.environ.get("GPR3D_FAST_EXIT", "1") != "0":
        os._exit(int(rc))
    sys.exit(rc)


def entry() -> None:
    """The ``gpr3d`` console command: :func:`main`, then :func:`leave`."""
    leave(main())


if __name__ == "__main__":
    entry()
