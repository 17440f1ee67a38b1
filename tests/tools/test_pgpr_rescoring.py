"""benchmarks/pgpr_rescoring.py: wrong arguments are one line each, before any detection; its class-averaged rows
score a box under its kind at its score and under the others at score x share."""

import numpy as np
import pytest

from tests.tools._script import refusal


@pytest.mark.parametrize("args, line", [
    (["--weights", "9"], "--weights must lie in 0..8, got 9"),
    (["--weights", "1", "-0.5"], "--weights must lie in 0..8, got 1 -0.5"),
    (["--pgpr", "{tmp}"], "--pgpr {tmp}: no train/ folder in it (P-GPR's train/ and val/)"),
])
def test_wrong_arguments_are_one_line(tmp_path, args, line):
    got = refusal("pgpr_rescoring.py", *(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert got == "pgpr_rescoring.py: error: " + line.replace("{tmp}", str(tmp_path))


def test_its_metrics_are_the_evaluation_s():
    pytest.importorskip("pycocotools")
    import importlib.util
    import sys
    from pathlib import Path

    from gpr3d.core.survey import Survey
    from gpr3d.detection.evaluate import evaluate_detector

    root = Path(__file__).resolve().parents[2]
    sys.path.insert(0, str(root / "benchmarks"))
    spec = importlib.util.spec_from_file_location("pgpr_rescoring", root / "benchmarks" / "pgpr_rescoring.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    kinds = ["rebar", "pvc_pipe", "void"]
    dt = 1e-10
    labels = np.array([[10, 1e-9, 30, 3e-9], [50, 2e-9, 70, 4e-9], [75, 1e-9, 95, 3e-9]])
    boxes = np.array([[30, 5e-9, 45, 7e-9], [11, 1e-9, 30, 3.2e-9], [50, 2.1e-9, 72, 4e-9], [74, 1e-9, 95, 2.8e-9]])
    scores = np.array([0.95, 0.9, 0.8, 0.5])
    probs = np.array([[0.6, 0.4, 0], [0.8, 0.2, 0], [0.6, 0.3, 0.1], [0.1, 0.9, 0]])
    rec = mod.with_iou([{"dt": dt, "boxes": boxes, "scores": scores, "probs": probs, "labels": labels,
                         "kinds": ["rebar", "pvc_pipe", "pvc_pipe"]}])
    assert rec[0]["iou"][0] == 0 and rec[0]["iou"][1] == pytest.approx(380 / 438, abs=1e-9)  # 19 x 20 shared of 19 x 22 and 20 x 20

    class Stub:
        def detect(self, survey, score_threshold):
            return {"n_windows": 1, "targets": [
                {"box": list(b), "score": s, "apex_trace": 0, "apex_time_s": 0.0, "kind": kinds[int(np.argmax(p))],
                 "kind_shares": dict(zip(kinds, p))} for b, s, p in zip(boxes, scores, probs)]}

    Stub.kinds = kinds
    lab = {"labels": [{"box": list(b), "apex_trace": 0, "apex_time_s": 0.0, "kind": k}
                      for b, k in zip(labels, rec[0]["kinds"])]}
    want = evaluate_detector(Stub(), [(Survey(data=np.zeros((100, 80), np.float32), dt_s=dt), lab)])
    got = mod.metrics(rec, kinds, [scores])
    for key in ("mAP@0.5", "mAP@0.75", "mAP", "AR@100", "recall@0.5"):
        assert got[key] == pytest.approx(want["by_kind"][key], abs=1e-12), key
    assert got["agnostic"] == pytest.approx(want["mAP"], abs=1e-12)
    # the box false but sure of itself first: rebar's AP is 1/2 (box f at 0.95 above the true 0.9)
    assert got["mAP@0.5"] < 1 and mod.metrics(rec, kinds, [np.array([0.1, 0.9, 0.8, 0.5])])["mAP@0.5"] == 1
