"""``gpr3d info``: print what radar files hold."""

from __future__ import annotations

import json
import sys

from gpr3d.core.errors import GPR3DError


def _print_survey_info(path, surveys, as_json: bool):
    rows = []
    for s in surveys:
        m = s.metadata
        row = {
            "file": str(path),
            "format": m.get("format"),
            "channel": m.get("channel", 0),
            "n_traces": s.n_traces,
            "n_samples": s.n_samples,
            "dt_s": s.dt_s,
            "range_s": s.time_window_s,
            "antenna": m.get("antenna"),
            "frequency_hz": s.frequency_hz,
            "offset_m": s.offset_m,
            "eps_r": s.eps_r,
            "date": m.get("created") or m.get("date"),
            "positions": m.get("positions_source"),
            "length_m": None if s.distances_m is None else float(s.distances_m[-1]),
            "history": [h["step"] for h in s.history],
            "header_timewindow_s": m.get("header_timewindow_s"),
        }
        rows.append(row)
    if as_json:
        return rows
    for r in rows:
        ch = f" channel {r['channel']}" if len(rows) > 1 else ""
        print(f"{r['file']}{ch}: {r['format']}")
        print(f"  traces x samples : {r['n_traces']} x {r['n_samples']}")
        print(f"  sample interval  : {r['dt_s'] * 1e9:.6g} ns   range: {r['range_s'] * 1e9:.6g} ns")
        if r["header_timewindow_s"] and abs(r["header_timewindow_s"] - r["range_s"]) > 1e-3 * r["range_s"]:
            print(f"  header window    : {r['header_timewindow_s'] * 1e9:.6g} ns (TIMEWINDOW field; the range above"
                  " follows the sampling frequency)")
        ant = r["antenna"] or "?"
        freq = f"{r['frequency_hz'] / 1e6:.6g} MHz" if r["frequency_hz"] else "unknown frequency"
        print(f"  antenna          : {ant} ({freq}), tx-rx offset {r['offset_m']:.4g} m")
        if r["eps_r"]:
            print(f"  eps_r (header)   : {r['eps_r']:.4g}")
        if r["date"]:
            print(f"  recorded         : {r['date']}")
        if r["positions"] and r["length_m"] is not None:
            print(f"  positions        : {r['positions']}; path length {r['length_m']:.4g} m")
        elif r["positions"]:  # (no positions: the source says why, e.g. a gprMax file that kept no geometry)
            print(f"  positions        : {r['positions']}")
        if r["history"]:
            print(f"  processing       : {', '.join(r['history'])}")
    return rows


NAME = "info"
HELP = "print what radar files hold"
EPILOG = "example:\n  gpr3d info FILE____032.DZT XLINE00.DT1 --json"


def add_arguments(sp):
    sp.add_argument("files", nargs="+", help="radar files")
    sp.add_argument("--format", default=None, help="force a reader")
    sp.add_argument("--json", action="store_true", help="print JSON instead of text")


def run(args):
    from gpr3d.io.registry import read_all

    out, failed = [], 0
    for path in args.files:
        try:
            surveys = read_all(path, format=args.format)
        except (GPR3DError, MemoryError) as exc:
            if len(args.files) == 1:
                raise
            print(f"gpr3d: error: {exc if isinstance(exc, GPR3DError) else f'{path}: out of memory'}", file=sys.stderr)
            failed += 1
            continue
        out.extend(_print_survey_info(path, surveys, args.json))
    if args.json:
        print(json.dumps(out, indent=2))
    return 1 if failed else 0
