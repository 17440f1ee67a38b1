"""Where the direct wave's envelope peaks between the air wave and the ground wave (the hyperbola fit's time zero).

    python benchmarks/eval_time_zero.py [--survey datasets/gprmax_survey_train.h5] [--n 40] [--no-example]

With antennas on the ground the direct wave mixes the air wave (``h / c`` after the pulse leaves) and the ground
wave (``h / v``); :func:`gpr3d.inversion.hyperbola.time_zero` places its envelope peak a share ``mix`` of the way
from the first to the second (``DIRECT_WAVE_MIX``). This measures that share on gprMax records whose time zero is
known (gprMax's Ricker peaks ``sqrt(2) / f`` after the start): per record ``(peak - t0 - h/c) / (h/v - h/c)``, with
the peak from :func:`direct_wave_time`, the true eps_r and the antenna offset. ``DIRECT_WAVE_MIX`` is the median
over the training twin's records (never the held-out set, never gprMax's example, which is reported beside it).
Writes ``benchmarks/results/time_zero.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402


def share(survey, eps_r: float) -> float:
    """The direct wave's envelope peak as a share of the way from the air wave to the ground wave."""
    from gpr3d.core.units import C0
    from gpr3d.inversion.hyperbola import direct_wave_time

    h, v = survey.offset_m, C0 / math.sqrt(eps_r)
    t0 = math.sqrt(2.0) / survey.frequency_hz
    return (direct_wave_time(survey)[0] - t0 - h / C0) / (h / v - h / C0)


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return n


def main(argv=None):
    from gpr3d.inversion.hyperbola import DIRECT_WAVE_MIX

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--survey", action="append", default=None,
                   help="packed gprMax survey file(s) (default: the training twin and the held-out set)")
    p.add_argument("--n", type=_positive, default=40, help="first N records of each file")
    p.add_argument("--no-example", action="store_true", help="skip gprMax's cylinder_Bscan_2D example")
    p.add_argument("--work", default=str(ROOT / "build" / "gprmax_example"))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    args = p.parse_args(argv)
    surveys = args.survey or [str(ROOT / "datasets" / "gprmax_survey_train.h5"), str(ROOT / "datasets" / "gprmax_survey.h5")]
    from gpr3d.io.packed import labelled_records

    rows = []
    for path in surveys:
        if not Path(path).exists():
            print(f"skipped {path}: not found")
            continue
        s = np.array([share(rec, lab["eps_r"]) for rec, lab in labelled_records(path, n=args.n)])
        rows.append((Path(path).name, s))
    if not args.no_example:
        from eval_depth_fit import gprmax_example

        rows.append(("gprMax example cylinder_Bscan_2D", np.array([share(gprmax_example(Path(args.work)), 6.0)])))
    lines = [f"Host CPU: {cpu_name()}", "", f"DIRECT_WAVE_MIX in use: {DIRECT_WAVE_MIX}", "",
             "| records | n | median share | mean | std | min | max |", "|---|---|---|---|---|---|---|"]
    for name, s in rows:
        lines.append(f"| {name} | {s.size} | {np.median(s):.3f} | {s.mean():.3f} | {s.std():.3f} | {s.min():.3f} | "
                     f"{s.max():.3f} |")
    write_table(args.out, "time_zero.md", "\n".join(lines), "eval_time_zero.py", argv)


if __name__ == "__main__":
    main()
