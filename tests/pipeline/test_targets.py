"""gpr3d.pipeline's middle stages: depths put into a detection result, and targets read from a file, checked."""

import json
import math

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline import add_depths, load_models, read_targets, targets_from_file


@pytest.fixture(scope="module")
def record():
    from gpr3d.simulation.surveys import survey_sample

    s, lab = survey_sample(777, 5)
    targets = [{"box": b["box"], "apex_trace": b["apex_trace"], "apex_time_s": b["apex_time_s"], "score": 1.0}
               for b in lab["labels"] if b["visible"]]
    assert targets
    return s, lab, targets


def test_depths_are_those_the_estimator_gives_put_on_each_target(record):
    from gpr3d.inversion.estimate import estimate_depths

    s, _, targets = record
    found = {"input": "sample", "targets": [dict(t) for t in targets]}
    add_depths(s, found, "fit")
    ref = estimate_depths(s, [dict(t) for t in targets], method="fit")
    assert found["permittivity"]["eps_r"] == ref["permittivity"]["eps_r"]
    assert found["permittivity"]["method"] == "fit"
    for t, e in zip(found["targets"], ref["targets"]):
        assert t["x_m"] == e["x_m"]
        assert t["depth_m"] == (e["depth_m"] if math.isfinite(e["depth_m"]) else None)
    assert 1.0 < found["permittivity"]["eps_r"] < 40.0  # (its accuracy: tests/inversion, benchmarks/eval_depth.py)


def test_no_positions_and_no_spacing_warn_and_add_nothing(record):
    s, _, targets = record
    bare = Survey(data=s.data, dt_s=s.dt_s, frequency_hz=s.frequency_hz)
    found = {"input": "bare.h5", "targets": [dict(t) for t in targets]}
    with pytest.warns(UserWarning, match="bare.h5: the file has no trace positions"):
        add_depths(bare, found, "fit")
    assert "permittivity" not in found and "depth_m" not in found["targets"][0]
    from gpr3d.inversion.estimate import estimate_depths

    dx = float(np.diff(s.distances_m).mean())
    spaced = {"input": "bare.h5", "targets": [dict(t) for t in targets]}
    add_depths(bare, spaced, "fit", trace_spacing_m=dx)  # the spacing given stands in for the positions
    ref = estimate_depths(bare, [dict(t) for t in targets], method="fit", trace_spacing_m=dx)
    assert spaced["permittivity"]["eps_r"] == ref["permittivity"]["eps_r"]
    assert [t["x_m"] for t in spaced["targets"]] == [e["x_m"] for e in ref["targets"]]


def test_targets_from_a_file_are_cut_to_the_record_and_bad_apexes_dropped():
    s = Survey(data=np.zeros((100, 200)), dt_s=1e-10)  # 100 traces, 19.9 ns
    window = 199e-10
    got = targets_from_file("d.json", [
        {"box": [-5, -1e-9, 50, 5e-9], "apex_trace": 20, "apex_time_s": 2e-9},
        {"box": [60, 1e-9, 130, 30e-9], "apex_trace": float("nan"), "apex_time_s": 3e-9},
        {"box": [10, 1e-9, 20, 2e-9], "apex_trace": True, "apex_time_s": 1.5e-9},
    ], s)
    assert got[0]["box"] == [0.0, 0.0, 50, 5e-9] and got[0]["apex_trace"] == 20
    assert got[1]["box"] == [60, 1e-9, 99.0, window] and "apex_trace" not in got[1] and "apex_time_s" not in got[1]
    assert "apex_trace" not in got[2]  # a bool is no trace number
    with pytest.raises(GPR3DError, match=r"^d.json: .*box"):
        targets_from_file("d.json", [{"box": [500, 1e-9, 600, 2e-9]}], s)  # wholly past the record


def test_a_detections_file_reads_as_a_result_and_a_missing_channel_is_one_line(tmp_path):
    s = Survey(data=np.zeros((100, 200)), dt_s=1e-10)
    doc = {"input": "x", "n_traces": 100, "dt_s": 1e-10, "targets": [{"box": [1, 1e-9, 30, 4e-9], "score": 0.9}]}
    (tmp_path / "d.json").write_text(json.dumps(doc))
    r = read_targets(tmp_path / "d.json", s, input_name="line.h5")
    assert r["input"] == "line.h5" and r["targets"][0]["box"] == [1, 1e-9, 30, 4e-9]
    with pytest.raises(GPR3DError, match=r"d.json: has 1 channel\(s\); no channel 2"):
        read_targets(tmp_path / "d.json", s, channel=2)


def test_models_are_loaded_only_as_asked():
    assert load_models(detector=False, depth="fit") == (None, None)
    det, net = load_models(detector=False, depth="net")
    from gpr3d.inversion.depthnet import DepthEstimator

    assert det is None and isinstance(net, DepthEstimator)
    with pytest.raises(GPR3DError, match="nosuch.pt"):
        load_models(weights="nosuch.pt", depth="none")
