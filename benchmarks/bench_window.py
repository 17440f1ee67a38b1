"""What one detector window costs on the CPU, stage by stage: the window live mode runs as its traces fill
(``gpr3d live``) and ``gpr3d detect`` runs along a record. With ``--base REV``, the shipped ONNX graph of
revision REV (or with ``--other FILE`` any ONNX detector graph) is timed against the working tree's in the same
process, round after round, on the same windows.

The windows: the first 256 traces of ``--windows`` survey-scale synthetic records
(``gpr3d.simulation.surveys.survey_sample(777, i)``: deterministic, no data files needed), each detected as live
mode detects a full window (the shipped detector and box refiner, ONNX Runtime, its threads sleeping between
runs, score 0.5). What is timed: ``Detector.detect`` on each window (after one untimed warm-up), split into its
stages (``gpr3d.core.timing``): prepare (dewow, background, resampling, equalising), windows (rendering the
image), network, merge, refine, apexes. With ``--base``, only the network graphs are compared (the rest of the
code is the working tree's), each graph on every window, the two alternating; the table gives both medians, on how
many windows both keep as many boxes (score >= 0.5), and there how far each box is from the other's nearest (px).

    python benchmarks/bench_window.py [--windows 12] [--rounds 3] [--base REV | --other FILE] [--out DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, write_table  # noqa: E402

import argparse  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GRAPH = "src/gpr3d/detection/default_detector.onnx"
TRACES = 256


def base_graph(rev: str) -> Path:
    """The shipped ONNX graph of revision ``rev``, written into a temporary folder; a one-line SystemExit where git
    has no such revision or the revision no such file."""
    got = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{GRAPH}"], capture_output=True)
    if got.returncode != 0:
        why = got.stderr.decode(errors="replace").strip().splitlines()
        raise SystemExit(f"--base {rev}: {why[-1] if why else 'git show failed'}")
    path = Path(tempfile.mkdtemp(prefix="gpr3d-bench-window-")) / "base.onnx"
    path.write_bytes(got.stdout)
    return path


def records(n: int) -> list:
    """The first ``TRACES`` traces of ``n`` synthetic records, as live mode hands a window to its detector (the
    samples, their interval, the frequency and the antenna offset)."""
    from gpr3d.core.survey import Survey
    from gpr3d.simulation.surveys import survey_sample

    out = []
    for i in range(n):
        s, _ = survey_sample(777, i)
        out.append(Survey(data=s.data[:TRACES], dt_s=s.dt_s, frequency_hz=s.frequency_hz, offset_m=s.offset_m))
    return out


def stage_table(det, surveys, rounds: int) -> tuple[dict, float]:
    """Median milliseconds per window of each stage, and of the whole call, over ``rounds`` passes."""
    from gpr3d.core.timing import collect

    per = {}
    whole = []
    for _ in range(rounds):
        for s in surveys:
            t = time.perf_counter()
            with collect(compile_times=False) as c:
                det.detect(s, score_threshold=0.5)
            whole.append(time.perf_counter() - t)
            for k, v in c.seconds.items():
                per.setdefault(k, []).append(v)
    return {k: 1e3 * float(np.median(v)) for k, v in per.items()}, 1e3 * float(np.median(whole))


def network_ab(paths: dict, surveys, rounds: int) -> dict:
    """``{name: (median ms, boxes)}`` of each graph's network on every window's image, the graphs alternating."""
    from gpr3d.detection.ort import OnnxDetector
    from gpr3d.detection.windows import prepare, windows

    dets = {k: OnnxDetector.load(p) for k, p in paths.items()}
    for d in dets.values():
        d.share_cores()
    any_det = next(iter(dets.values()))
    images = [windows(s, any_det.window, processed=prepare(s, any_det.window))[0].image for s in surveys]
    times = {k: [] for k in dets}
    boxes = {k: [] for k in dets}
    for d in dets.values():
        d.predict_windows([images[0]])  # (warm-up)
    for r in range(rounds):
        for im in images:
            for k, d in dets.items():
                t = time.perf_counter()
                got = d.predict_windows([im])
                times[k].append(time.perf_counter() - t)
                if r == 0:
                    boxes[k].append(got[0][0][got[0][1] >= 0.5])  # (the boxes a detection would keep)
    return {k: (1e3 * float(np.median(times[k])), boxes[k]) for k in dets}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--windows", type=int, default=12, help="windows (one per synthetic record)")
    ap.add_argument("--rounds", type=int, default=3, help="passes over the windows")
    ap.add_argument("--base", default=None, help="a git revision whose shipped ONNX graph to time against")
    ap.add_argument("--other", default=None, help="an ONNX detector graph to time against (e.g. an 8-bit one made by "
                    "references/detection/quantize_onnx.py)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    ap.add_argument("--name", default="bench_window.md", help="the result file's name in --out")
    args = ap.parse_args(argv)
    if not 1 <= args.windows <= 500:
        raise SystemExit(f"--windows must lie in 1..500, got {args.windows}")
    if not 1 <= args.rounds <= 100:
        raise SystemExit(f"--rounds must lie in 1..100, got {args.rounds}")
    if Path(args.name).name != args.name or not args.name.endswith(".md"):
        raise SystemExit(f"--name {args.name}: a file name ending in .md")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise SystemExit(f"--out {out}: not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SystemExit(f"--out {out}: {exc.strerror}") from None
    if args.base and args.other:
        raise SystemExit("--base and --other: give one graph to time against")
    if args.other and not Path(args.other).is_file():
        raise SystemExit(f"--other {args.other}: no such file")
    base = base_graph(args.base) if args.base else (Path(args.other) if args.other else None)
    label = args.base or (Path(args.other).name if args.other else None)

    from gpr3d.detection.infer import load_detector

    det = load_detector(engine="onnx")
    det.share_cores()
    surveys = records(args.windows)
    det.detect(surveys[0], score_threshold=0.5)  # (warm-up)
    stages, whole = stage_table(det, surveys, args.rounds)
    lines = [f"Host CPU: {cpu_name()}, {os.cpu_count()} cores (ONNX Runtime: a thread per core); the shipped detector and refiner (ONNX Runtime) on "
             f"{args.windows} windows of {TRACES} traces (survey_sample(777, i), i < {args.windows}), "
             f"{args.rounds} rounds; median ms per window", "",
             "| stage | ms |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in stages.items()]
    lines.append(f"| whole call | {whole:.1f} |")
    if base is not None:
        got = network_ab({"base": base, "tree": ROOT / GRAPH}, surveys, args.rounds)
        pairs = [(a, b) for a, b in zip(got["base"][1], got["tree"][1]) if a.shape == b.shape]
        # each box scoring 0.5 or more against the other graph's nearest (near-equal scores may swap places)
        diff = max((float(np.abs(b[:, None] - a[None]).max(axis=2).min(axis=1).max()) for a, b in pairs if a.size),
                   default=0.0)
        lines += ["", f"The network alone, the two graphs alternating on the same windows (as many boxes scoring "
                      f"0.5 or more from both on {len(pairs)} of {len(surveys)} windows; there, each box within "
                      f"{diff:.2g} px of the other graph's nearest):",
                  "", "| graph | median ms |", "|---|---|",
                  f"| {label} | {got['base'][0]:.1f} |", f"| working tree | {got['tree'][0]:.1f} |"]
    write_table(out, args.name, "\n".join(lines), "bench_window.py", argv)


if __name__ == "__main__":
    main()
