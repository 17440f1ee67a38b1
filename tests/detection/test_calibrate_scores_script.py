"""references/detection/calibrate_scores.py: refusals before any work, and a fit on a few synthetic records whose
map the written weights then apply to every score."""

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("torch")

from tests.conftest import REPO  # noqa: E402

SCRIPT = REPO / "references" / "detection" / "calibrate_scores.py"
WEIGHTS = REPO / "src" / "gpr3d" / "detection" / "default_detector.pt"


@pytest.mark.parametrize("extra, said", [
    ([], "nothing to calibrate on"),
    (["--synthetic", "1000:5"], "seed 1000 is the detectors' training source"),
    (["--synthetic", "777:5"], "seed 777 is the shipped weights' check set"),
    (["--synthetic", "5:x"], "--synthetic 5:x: expected NAME:N with N a whole number >= 1"),
    (["--synthetic", "abc:3"], "the seed must be a whole number"),
    (["--packed", "absent.h5:3"], "--packed absent.h5: no such file"),
    (["--packed", "datasets/gprmax400.h5:0"], "expected NAME:N with N a whole number >= 1"),
    (["--packed", "datasets/gprmax400.h5:401"], "--packed datasets/gprmax400.h5:401: the file holds 400 records"),
    (["--packed", "README.md:3"], "--packed README.md: README.md: HDF5 content is corrupt or truncated"),
    (["--out", "cal.txt", "--synthetic", "5:1"], "--out cal.txt: a .pt file in an existing folder"),
])
def test_wrong_arguments_are_one_line_and_write_nothing(tmp_path, extra, said):
    out = tmp_path / "cal.pt"
    first = [] if "--out" in extra else ["--out", str(out)]
    r = subprocess.run([sys.executable, str(SCRIPT), str(WEIGHTS), *first, *extra], capture_output=True,
                       text=True, timeout=120, cwd=REPO)
    assert r.returncode == 2 and said in r.stderr.strip().splitlines()[-1]
    assert not out.exists()


def test_weights_that_are_not_a_pt_file_are_one_line(tmp_path):
    onnx = REPO / "src" / "gpr3d" / "detection" / "default_detector.onnx"
    r = subprocess.run([sys.executable, str(SCRIPT), str(onnx), "--out", str(tmp_path / "c.pt"), "--synthetic", "5:1"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].endswith(
        "default_detector.onnx: calibrate a .pt weights file (then export it: its graph carries the map)")


def test_the_fit_lands_in_the_weights_and_every_score_goes_through_it(tmp_path):
    import torch

    from gpr3d.detection.calibration import calibrate
    from gpr3d.detection.infer import load_detector
    from gpr3d.simulation.surveys import survey_sample

    sys.path.insert(0, str(SCRIPT.parent))
    import calibrate_scores

    before = WEIGHTS.read_bytes()
    out = tmp_path / "cal.pt"
    calibrate_scores.main([str(WEIGHTS), "--out", str(out), "--synthetic", "4242:3", "--refiner", "none"])
    assert WEIGHTS.read_bytes() == before  # the input is left as it was
    cal = torch.load(out, weights_only=True)["provenance"]["score_calibration"]
    assert cal["method"] == "platt" and cal["a"] > 0 and cal["fit_on"] == "survey_sample(4242, i < 3)"
    raw = load_detector(WEIGHTS, engine="torch", refiner="none")
    raw.calibration = None
    recs = [survey_sample(4242, i) for i in range(3)]
    found = [raw.detect(s, score_threshold=0.05)["targets"] for s, _ in recs]
    assert cal["n_boxes"] == sum(len(f) for f in found) and 0 < cal["n_true"] < cal["n_boxes"]
    det = load_detector(out, engine="torch", refiner="none")
    assert det.calibration["a"] == cal["a"]
    got = det.detect(recs[0][0], score_threshold=0.0)["targets"]
    every = raw.detect(recs[0][0], score_threshold=0.0)["targets"]
    assert [t["box"] for t in got] == [t["box"] for t in every]  # the same boxes in the same order
    assert np.allclose([t["score"] for t in got], calibrate([t["score"] for t in every], cal), rtol=0, atol=1e-12)
