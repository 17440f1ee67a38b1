"""Run detectors on the held-out survey set and dump raw detections (for metrics on another machine).

    PYTHONPATH=src python references/detection/dump_detections.py OUT.json W1.pt W2.pt ... [--device cuda]
"""
import json, sys
from gpr3d.detection.infer import Detector
from gpr3d.simulation.surveys import survey_sample

args = [a for a in sys.argv[1:] if not a.startswith("--")]
device = "cuda" if "--device" in sys.argv and "cuda" in sys.argv else "cpu"
out, weights = args[0], args[1:]
recs = [survey_sample(777, i) for i in range(30)]
res = {}
for w in weights:
    det = Detector.load(w, device=device)
    name = det.provenance.get("name", w)
    res[name] = {"provenance": {k: v for k, v in det.provenance.items() if k != "config"},
                 "steps": det.provenance.get("config", {}).get("steps"),
                 "records": [det.detect(s, score_threshold=0.0) for s, _ in recs]}
    print(name, flush=True)
json.dump(res, open(out, "w"))
