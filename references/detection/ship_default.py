"""Make a trained weights file the shipped default detector: copy, provenance, check set, ONNX export.

    python references/detection/ship_default.py runs/ft_pgpr/weights.pt --stage stage_4 \
        --what "fine-tuned on P-GPR train ..." --command "python references/detection/finetune_pgpr.py ..."

Writes ``src/gpr3d/detection/default_detector.pt`` and ``.onnx`` (the torch-free engine's export), and adds the
stage to ``default_detector.json`` with the file's SHA-256, the weights' own provenance (credit included) and the
fixed check set's metrics re-measured (``survey_sample(777, i)``, i < 4, score 0.5), which the test suite holds
the shipped weights to. Weights calibrated by ``calibrate_scores.py`` have their Platt map copied to the JSON's
``score_calibration``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil

from gpr3d.core.atomic import atomic_write_text
from gpr3d.detection.evaluate import evaluate_detector
from gpr3d.detection.infer import Detector
from gpr3d.detection.ort import export_onnx
from gpr3d.detection.weights import DEFAULT_WEIGHTS, load_weights
from gpr3d.simulation.surveys import survey_sample


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("weights")
    p.add_argument("--stage", required=True, help="the provenance entry's name, e.g. stage_4")
    p.add_argument("--what", required=True, help="what this stage did, in words")
    p.add_argument("--command", required=True, help="the command that made the weights")
    p.add_argument("--device", default="cpu (2 cores)", help="where it trained")
    p.add_argument("--extra", default="{}", help="more fields for the stage, as JSON")
    args = p.parse_args(argv)
    _, _, prov = load_weights(args.weights)  # a wrong file fails here, before anything is replaced
    meta_path = DEFAULT_WEIGHTS.with_suffix(".json")
    meta = json.loads(meta_path.read_text())
    shutil.copyfile(args.weights, DEFAULT_WEIGHTS)
    stage = {"what": args.what, "command": args.command, "device": args.device,
             "steps_done": prov.get("steps_done"), "train_wall_s": prov.get("train_wall_s"),
             "data": prov.get("data"), "credit": prov.get("credit"), **json.loads(args.extra)}
    meta["training"][args.stage] = {k: v for k, v in stage.items() if v is not None}
    if prov.get("score_calibration"):  # (calibrate_scores.py: the Platt map every score goes through)
        meta["score_calibration"] = prov["score_calibration"]
    else:
        meta.pop("score_calibration", None)
    meta["sha256"] = hashlib.sha256(DEFAULT_WEIGHTS.read_bytes()).hexdigest()
    model, _, _ = load_weights(DEFAULT_WEIGHTS)
    meta["kinds"] = getattr(model, "gpr3d_kinds", None)
    check = meta["check"]
    m = evaluate_detector(Detector.load(), [survey_sample(check["seed"], i) for i in range(check["n"])],
                          score_threshold=check["score_threshold"])
    check["metrics"] = {k: m[k] for k in ("mAP@0.5", "mAP@0.75", "AR@100", "apex_recall", "false_per_true")}
    atomic_write_text(meta_path, json.dumps(meta, indent=1) + "\n")
    print(json.dumps({"sha256": meta["sha256"], "check": check["metrics"], "onnx": export_onnx()}))


if __name__ == "__main__":
    main()
