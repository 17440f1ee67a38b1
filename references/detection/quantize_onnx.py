"""The shipped 8-bit detector graph (``src/gpr3d/detection/default_detector_int8.onnx``, live mode's default):
the shipped float graph's convolutions and box-head layers quantised by ONNX Runtime's static quantisation
(:func:`gpr3d.detection.ort.quantise_onnx`), calibrated on detector windows of real and synthetic records.

    python references/detection/quantize_onnx.py [OUT.onnx] [--full-range] [--pgpr DIR] [--records 24]

Calibration windows: every window of ``--records`` P-GPR train pictures (shuffled with seed 0; skipped with a
note when ``--pgpr`` is absent) and the first window of 16 survey-scale synthetic records
(``survey_sample(777, i)``); 155 windows in all, about 15 s on 2 cores. P-GPR: Yue, Qin, Zhu, Ye, Wang,
"P-GPR: a Ground Penetrating Radar Dataset for Pipeline Detection", CIKM '26, CC BY 4.0 (the graph's metadata
credits it). Weights keep to 7 bits unless ``--full-range`` (which only CPUs with VNNI multiply without
saturating). Rerun it whenever the float graph is re-exported: a test checks that the 8-bit graph names the
float graph's SHA-256. The gpr3d metadata travels with the graph, so the benchmarks take it as they take the
float one:

    python benchmarks/eval_pgpr.py default src/gpr3d/detection/default_detector_int8.onnx --out /tmp/q
    python benchmarks/eval_detector.py default src/gpr3d/detection/default_detector_int8.onnx --runtime onnx --out /tmp/q
"""

from __future__ import annotations

import argparse
import random
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
CREDIT = ("P-GPR dataset (train split): Yue, Qin, Zhu, Ye, Wang, 'P-GPR: a Ground Penetrating Radar Dataset for "
          "Pipeline Detection', CIKM '26; repository aiiseverything/P-GPR-Dataset; licence CC BY 4.0")


def calibration_images(pgpr: Path, n_records: int) -> tuple[list, str]:
    """The calibration windows and a line saying what they are."""
    from bench_window import records

    from gpr3d.detection.ort import OnnxDetector
    from gpr3d.detection.windows import prepare, windows

    cfg = OnnxDetector.load().window
    images, said = [], []
    if n_records and (pgpr / "train").is_dir():
        from eval_pgpr import pgpr_records

        recs = pgpr_records(pgpr, "train")
        random.Random(0).shuffle(recs)
        for survey, _ in recs[:n_records]:
            images += [w.image for w in windows(survey, cfg, processed=prepare(survey, cfg))]
        said.append(f"every window ({len(images)}) of {min(n_records, len(recs))} P-GPR train pictures (shuffled "
                    f"with seed 0; {CREDIT})")
    elif n_records:
        print(f"no P-GPR train split in {pgpr}: calibrating on synthetic records only", file=sys.stderr)
    images += [windows(s, cfg, processed=prepare(s, cfg))[0].image for s in records(16)]
    said.append("the first window of 16 survey-scale synthetic records (survey_sample(777, i), i < 16)")
    return images, "; ".join(said)


def main(argv=None) -> None:
    from gpr3d.detection.ort import DEFAULT_INT8

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", nargs="?", default=str(DEFAULT_INT8), help="the 8-bit graph to write (.onnx; default: "
                   "the shipped one)")
    p.add_argument("--full-range", action="store_true", help="8-bit weights (saturate on CPUs without VNNI)")
    p.add_argument("--pgpr", default=str(ROOT.parent / "shared" / "data" / "real" / "pgpr_1600MHz"))
    p.add_argument("--records", type=int, default=24, help="P-GPR train pictures to calibrate on")
    args = p.parse_args(argv)
    out = Path(args.out)
    if out.suffix.lower() != ".onnx":
        raise SystemExit(f"{out}: the output must be an .onnx file")
    if not out.parent.is_dir():
        raise SystemExit(f"{out.parent}: no such folder")
    if not 0 <= args.records <= 1000:
        raise SystemExit(f"--records must lie in 0..1000, got {args.records}")
    from gpr3d.detection.ort import quantise_onnx

    images, said = calibration_images(Path(args.pgpr), args.records)
    cmd = shlex.join(["python", "references/detection/quantize_onnx.py"] + list(sys.argv[1:] if argv is None
                                                                                   else argv))
    got = quantise_onnx(images, out, reduce_range=not args.full_range, calibration=said, command=cmd)
    print(f"{out}: {got['bytes'] / 2**20:.1f} MiB, calibrated on {got['windows']} windows")


if __name__ == "__main__":
    main()
