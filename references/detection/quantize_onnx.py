"""An 8-bit version of the shipped ONNX detector (an experiment; not shipped): its convolutions quantised by ONNX
Runtime's static quantisation, calibrated on detector windows of real and synthetic records.

    python references/detection/quantize_onnx.py OUT.onnx [--reduce-range] [--pgpr DIR] [--records 24]

Calibration windows: every window of ``--records`` P-GPR train pictures (shuffled with seed 0; skipped with a
note when ``--pgpr`` is absent) and the first window of 16 survey-scale synthetic records
(``survey_sample(777, i)``). Only the ``Conv`` nodes are quantised (QDQ format, weights int8 per channel,
activations uint8); the region heads, the box decoding and NMS stay in float. ``--reduce-range`` keeps the
weights to 7 bits: on x86 CPUs without VNNI (AVX2 only, e.g. AMD Zen 3) ONNX Runtime's uint8 x int8 products may
saturate at full range. The gpr3d metadata travels with the graph, so ``load_detector(OUT.onnx)`` and the
benchmarks take it as they take the shipped one:

    python benchmarks/eval_pgpr.py default OUT.onnx --out /tmp/q
    python benchmarks/eval_detector.py default OUT.onnx --runtime onnx --out /tmp/q
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def calibration_images(pgpr: Path, n_records: int) -> list:
    from bench_window import records

    from gpr3d.detection.ort import OnnxDetector
    from gpr3d.detection.windows import prepare, windows

    cfg = OnnxDetector.load().window
    images = []
    if (pgpr / "train").is_dir():
        from eval_pgpr import pgpr_records

        recs = pgpr_records(pgpr, "train")
        random.Random(0).shuffle(recs)
        for survey, _ in recs[:n_records]:
            images += [w.image for w in windows(survey, cfg, processed=prepare(survey, cfg))]
    else:
        print(f"no P-GPR train split in {pgpr}: calibrating on synthetic records only", file=sys.stderr)
    images += [windows(s, cfg, processed=prepare(s, cfg))[0].image for s in records(16)]
    return images


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", help="the 8-bit graph to write (.onnx)")
    p.add_argument("--reduce-range", action="store_true", help="7-bit weights (CPUs without VNNI)")
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
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    from gpr3d.core.atomic import atomic_path
    from gpr3d.detection.ort import DEFAULT_ONNX

    images = calibration_images(Path(args.pgpr), args.records)

    class Windows(CalibrationDataReader):
        def __init__(self):
            self._it = iter([{"image": im} for im in images])

        def get_next(self):
            return next(self._it, None)

    with tempfile.TemporaryDirectory() as tmp:
        pre = Path(tmp) / "pre.onnx"
        quant_pre_process(str(DEFAULT_ONNX), str(pre), skip_symbolic_shape=True)
        with atomic_path(out, suffix=".onnx.part") as part:
            quantize_static(str(pre), str(part), Windows(), quant_format=QuantFormat.QDQ, per_channel=True,
                            op_types_to_quantize=["Conv"], activation_type=QuantType.QUInt8,
                            weight_type=QuantType.QInt8, reduce_range=args.reduce_range)
    print(f"{out}: {out.stat().st_size / 2**20:.1f} MiB, calibrated on {len(images)} windows")


if __name__ == "__main__":
    main()
