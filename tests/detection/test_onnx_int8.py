"""The 8-bit detector graph (live mode's default): the shipped float graph quantised, finding what it finds."""

import hashlib
import json

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
onnx = pytest.importorskip("onnx")

from onnx import numpy_helper  # noqa: E402

from gpr3d.core.errors import GPR3DError, InvalidDataError  # noqa: E402
from gpr3d.detection.infer import fastest_engine, load_detector  # noqa: E402
from gpr3d.detection.ort import DEFAULT_INT8, DEFAULT_ONNX, QUANTISED_OPS, OnnxDetector, quantise_onnx  # noqa: E402
from gpr3d.simulation.surveys import survey_sample  # noqa: E402


def _iou(a, b) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - w * h
    return w * h / union


def _weights_of(path, ops=QUANTISED_OPS) -> list:
    """For each node of ``ops`` in the graph: (its op, its weights as they are stored, or None where a float
    initializer feeds it directly)."""
    g = onnx.load(str(path)).graph
    inits = {t.name: t for t in g.initializer}
    made_by = {o: n for n in g.node for o in n.output}
    out = []
    for n in g.node:
        if n.op_type not in ops:
            continue
        dq = made_by.get(n.input[1])
        w = inits.get(dq.input[0]) if dq is not None and dq.op_type == "DequantizeLinear" else None
        out.append((n.op_type, None if w is None else numpy_helper.to_array(w)))
    return out


def test_the_shipped_8bit_graph_is_the_shipped_float_graph_quantised_and_says_how():
    det = OnnxDetector.load(DEFAULT_INT8)
    float_det = OnnxDetector.load()
    q = det.provenance["quantised"]
    # made from today's float graph: re-exporting it without re-quantising fails here
    assert q["source_sha256"] == hashlib.sha256(DEFAULT_ONNX.read_bytes()).hexdigest()
    assert q["source_graph"] == DEFAULT_ONNX.name and q["operators"] == ["Conv", "Gemm"]
    assert q["command"] == "python references/detection/quantize_onnx.py" and q["calibration_windows"] == 155
    assert "CC BY 4.0" in q["calibration"] and "P-GPR" in q["calibration"]  # the real pictures' credit
    assert q["weights"] == "int8 per channel, 7-bit range"
    assert det.provenance["name"] == float_det.provenance["name"] + " (8-bit)"
    assert det.window == float_det.window and det.kinds == float_det.kinds
    assert "quantised" not in float_det.provenance


def test_every_convolution_and_box_head_layer_of_the_shipped_graph_takes_7bit_weights():
    got = _weights_of(DEFAULT_INT8)
    ref = _weights_of(DEFAULT_ONNX)
    # as many convolutions and fully connected layers as the float graph, every one fed by 8-bit weights
    assert [op for op, _ in got] == [op for op, _ in ref] and {op for op, _ in got} == {"Conv", "Gemm"}
    assert all(w is not None and w.dtype == np.int8 for _, w in got)
    assert all(w is None for _, w in ref)
    # 7 bits: within -64..64 (no CPU saturates multiplying them by uint8 activations), and using that range
    peaks = [int(np.abs(w.astype(np.int32)).max()) for _, w in got]
    assert max(peaks) == 64 and min(peaks) >= 32
    g = onnx.load(str(DEFAULT_INT8)).graph
    assert not [t.name for t in g.initializer if t.data_type == onnx.TensorProto.FLOAT and t.name.endswith("weight")]


def test_the_8bit_graph_finds_the_boxes_the_float_graph_finds():
    """On synthetic records none of its calibration windows came from (the bounds: measured on these six records
    on an Intel rocketlake host, with room: worst box IoU 0.73, median 0.97, score 0.038 apart, one box more on
    one record)."""
    f, q = OnnxDetector.load(), OnnxDetector.load(DEFAULT_INT8)
    ious, apex, total = [], [], 0
    for seed, i in [(31, 0), (31, 1), (31, 2), (31, 3), (5, 0), (5, 1)]:
        s, _ = survey_sample(seed, i)
        a = f.detect(s, score_threshold=0.5)["targets"]
        b = q.detect(s, score_threshold=0.5)["targets"]
        assert abs(len(a) - len(b)) <= 2
        total += len(a)
        for x in a:
            best = max(b, key=lambda y: _iou(x["box"], y["box"]))
            ious.append(_iou(x["box"], best["box"]))
            assert ious[-1] >= 0.6 and abs(x["score"] - best["score"]) < 0.08
            apex.append(abs(x["apex_trace"] - best["apex_trace"]))
    assert total >= 40 and np.median(ious) >= 0.9
    # the apexes (found in the record within each box): 48 of 52 within 2 traces; the others 3, 9, 17 and 31 apart,
    # the last three in boxes at a record's first or last trace (a cut hyperbola's apex moves with a box edge)
    assert np.median(apex) <= 1 and np.mean(np.array(apex) <= 3) >= 0.9


def _windows(n=1):
    from gpr3d.detection.windows import prepare, windows

    cfg = OnnxDetector.load().window
    s, _ = survey_sample(31, 2)
    return [w.image for w in windows(s, cfg, processed=prepare(s, cfg))][:n]


def test_quantise_onnx_writes_an_8bit_graph_calibrated_on_the_windows_it_is_given(tmp_path):
    out = tmp_path / "q.onnx"
    got = quantise_onnx(_windows(1), out, reduce_range=False, calibration="one window", command="a test")
    assert got == {"file": str(out), "bytes": out.stat().st_size, "windows": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["q.onnx"]  # nothing left beside it
    g = onnx.load(str(out))
    assert [p.key for p in g.metadata_props] == ["gpr3d.detector"]  # (the quantiser's own entries dropped)
    meta = json.loads(g.metadata_props[0].value)
    base = json.loads(onnx.load(str(DEFAULT_ONNX)).metadata_props[0].value)
    q = meta.pop("quantised")
    assert meta == base  # the float graph's window, provenance and kinds, as they were
    assert q["calibration_windows"] == 1 and q["calibration"] == "one window" and q["command"] == "a test"
    assert q["weights"] == "int8 per channel" and q["source_sha256"] == hashlib.sha256(
        DEFAULT_ONNX.read_bytes()).hexdigest()
    assert max(int(np.abs(w.astype(np.int32)).max()) for _, w in _weights_of(out)) == 127  # full range
    # it detects: the float graph's boxes on a record, each one found again
    s, _ = survey_sample(31, 2)
    a = OnnxDetector.load().detect(s, score_threshold=0.5)["targets"]
    b = OnnxDetector.load(out).detect(s, score_threshold=0.5)["targets"]
    assert len(a) >= 5 and abs(len(a) - len(b)) <= 2
    assert np.median([max(_iou(x["box"], y["box"]) for y in b) for x in a]) >= 0.85


@pytest.mark.parametrize("images, message", [
    ([], "quantise_onnx needs at least one calibration window"),
    ([np.zeros((3, 8, 8), np.float32)], "calibration window 0: (3, 8, 8) values; the network takes finite"),
    ("nan", "calibration window 0: (3, "),
])
def test_quantise_onnx_refuses_windows_it_cannot_calibrate_on_before_writing(tmp_path, images, message):
    if images == "nan":
        images = _windows(1)
        images[0][1, 5, 5] = np.nan
        message += f"{images[0].shape[1]}, {images[0].shape[2]}) non-finite values"
    with pytest.raises(InvalidDataError) as err:
        quantise_onnx(images, tmp_path / "q.onnx")
    assert message in str(err.value) and len(str(err.value).splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_the_int8_engine_runs_the_shipped_8bit_graph_with_the_shipped_refiner(monkeypatch, tmp_path):
    from gpr3d.detection import ort
    from gpr3d.detection.weights import DEFAULT_WEIGHTS

    det = load_detector(engine="int8")
    assert isinstance(det, OnnxDetector) and det.path == DEFAULT_INT8 and det.refiner is not None
    assert load_detector().path == DEFAULT_ONNX  # (batch detection keeps the float graph)
    with pytest.raises(GPR3DError, match="--runtime int8 runs the shipped detector's 8-bit graph; for "):
        load_detector(DEFAULT_WEIGHTS, engine="int8")
    assert fastest_engine() == "int8"
    assert fastest_engine(DEFAULT_WEIGHTS) == "auto" and fastest_engine(None, "cuda") == "auto"
    monkeypatch.setattr(ort, "DEFAULT_INT8", tmp_path / "absent.onnx")
    assert fastest_engine() == "auto"  # (an install without the 8-bit graph)
