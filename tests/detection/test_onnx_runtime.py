"""The torch-free runtime: the shipped ONNX export gives the shipped weights' detections, NMS as torchvision's."""

import hashlib
import subprocess
import sys

import numpy as np
import pytest

ort = pytest.importorskip("onnxruntime")
torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from gpr3d.core.errors import GPR3DError  # noqa: E402
from gpr3d.detection.infer import Detector, load_detector  # noqa: E402
from gpr3d.detection.ort import DEFAULT_ONNX, OnnxDetector, onnx_nms  # noqa: E402
from gpr3d.detection.weights import DEFAULT_WEIGHTS  # noqa: E402


def test_onnx_nms_keeps_what_torchvision_keeps():
    from torchvision.ops import nms

    rng = np.random.default_rng(5)
    for n, iou in ((1, 0.5), (40, 0.5), (200, 0.3), (200, 0.7)):
        xy = rng.uniform(0, 100, (n, 2))
        wh = rng.uniform(5, 40, (n, 2))
        boxes = np.concatenate([xy, xy + wh], axis=1)
        scores = rng.random(n)
        want = nms(torch.as_tensor(boxes), torch.as_tensor(scores), iou).numpy()
        got = onnx_nms(boxes, scores, iou)
        np.testing.assert_array_equal(got, want)
    assert onnx_nms(np.zeros((0, 4)), np.zeros(0), 0.5).size == 0


def test_the_nms_graph_builder_makes_the_shipped_graph_and_it_runs_as_torchvision_s_nms():
    onnx = pytest.importorskip("onnx")
    from torchvision.ops import nms

    from gpr3d.detection import ort as gort

    built = gort.nms_graph()
    onnx.checker.check_model(built)
    shipped = onnx.load(str(gort.NMS_ONNX))
    assert built.graph == shipped.graph and list(built.opset_import) == list(shipped.opset_import)
    sess = ort.InferenceSession(built.SerializeToString(), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(9)
    xy = rng.uniform(0, 50, (60, 2))
    boxes = np.concatenate([xy, xy + rng.uniform(5, 30, (60, 2))], axis=1).astype(np.float32)
    scores = rng.random(60).astype(np.float32)
    sel = sess.run(None, {"boxes": boxes[None], "scores": scores[None, None], "max_out": np.array([60], np.int64),
                          "iou": np.array([0.4], np.float32)})[0]
    assert sel.dtype == np.int64 and sel.shape[1] == 3 and not sel[:, :2].any()  # batch 0, class 0
    np.testing.assert_array_equal(sel[:, 2], nms(torch.as_tensor(boxes), torch.as_tensor(scores), 0.4).numpy())


def test_merge_levels_puts_each_region_where_torchvision_s_scatter_does():
    from torchvision.ops.poolers import _onnx_merge_levels

    from gpr3d.detection.ort import merge_levels

    rng = np.random.default_rng(5)
    for n, n_levels in ((40, 3), (7, 4), (5, 2)):
        levels = torch.from_numpy(rng.integers(0, n_levels, n))
        levels[:n_levels] = torch.arange(n_levels)  # every level holds a region
        per_level = [torch.from_numpy(rng.random((int((levels == k).sum()), 3, 2, 2), dtype=np.float32))
                     for k in range(n_levels)]
        got = merge_levels(levels, per_level)
        assert torch.equal(got, _onnx_merge_levels(levels, per_level))
        # region i: the next unused row of its level's block, in order
        seen = [0] * n_levels
        for i, k in enumerate(levels.tolist()):
            assert torch.equal(got[i], per_level[k][seen[k]])
            seen[k] += 1


def test_the_shipped_graph_pools_by_gathering_regions_not_by_scattering_blocks():
    # torchvision's traced pooling scatters each level's (n_k, C, 7, 7) block with an index of that whole shape
    # (an Expand to 4-D in front of each ScatterElements); the shipped graph scatters region numbers only
    onnx = pytest.importorskip("onnx")
    g = onnx.load(str(DEFAULT_ONNX)).graph
    made_by = {o: node for node in g.node for o in node.output}
    scatters = [node for node in g.node if node.op_type == "ScatterElements"]
    assert len(scatters) == 1
    assert made_by[scatters[0].input[1]].op_type != "Expand"


def test_shipped_onnx_is_the_shipped_weights_and_detects_the_same():
    onnx_det = OnnxDetector.load()
    assert onnx_det.provenance.get("name") == Detector.load().provenance.get("name")
    meta = onnx_det.session.get_modelmeta().custom_metadata_map
    assert hashlib.sha256(DEFAULT_WEIGHTS.read_bytes()).hexdigest() in meta["gpr3d.detector"]
    from gpr3d.simulation.surveys import survey_sample

    s, _ = survey_sample(777, 5)
    a = Detector.load().detect(s, score_threshold=0.3)["targets"]
    b = onnx_det.detect(s, score_threshold=0.3)["targets"]
    assert len(a) == len(b) and len(a) > 0
    for x, y in zip(a, b):
        np.testing.assert_allclose(x["box"][::2], y["box"][::2], atol=0.05)  # traces
        np.testing.assert_allclose(x["box"][1::2], y["box"][1::2], atol=0.02 * s.dt_s)  # seconds
        assert abs(x["score"] - y["score"]) < 2e-3 and x["apex_trace"] == y["apex_trace"]


def test_a_graph_exported_before_every_kind_s_share_gives_its_best_kind_s_alone(tmp_path):
    onnx = pytest.importorskip("onnx")
    g = onnx.load(str(DEFAULT_ONNX))
    assert [o.name for o in g.graph.output][-2:] == ["kind_scores", "kind_probs"]
    g.graph.output.pop()  # the graph as exports made before 2026-12-06 were
    onnx.save(g, str(tmp_path / "old.onnx"))
    old, new = OnnxDetector.load(tmp_path / "old.onnx"), OnnxDetector.load()
    im = np.random.default_rng(4).random((3, new.window.rows, new.window.traces), dtype=np.float32)
    (b0, s0, l0, k0, p0), = old.predict_windows_kinds([im])
    (b1, s1, l1, k1, p1), = new.predict_windows_kinds([im])
    assert len(b0) > 3 and np.array_equal(b0, b1) and np.array_equal(s0, s1) and np.array_equal(k0, k1)
    want = np.zeros_like(p1)
    want[np.arange(len(l0)), l0 - 1] = k0
    assert np.array_equal(p0, want) and not np.array_equal(p1, want)
    np.testing.assert_allclose(p1[np.arange(len(l1)), l1 - 1], k1, atol=1e-6)


def test_a_detector_sharing_the_cores_stops_spinning_and_detects_the_same():
    """Live mode's detector: its session's threads sleep between runs (ONNX Runtime's session option), and the
    boxes are what they were."""
    from gpr3d.simulation.surveys import survey_sample

    det = OnnxDetector.load()
    s, _ = survey_sample(777, 5)
    before = det.detect(s, score_threshold=0.3)["targets"]
    with pytest.raises(Exception, match="allow_spinning"):  # (not set: ONNX Runtime's default, spinning)
        det.session.get_session_options().get_session_config_entry("session.intra_op.allow_spinning")
    det.share_cores()
    assert det.session.get_session_options().get_session_config_entry("session.intra_op.allow_spinning") == "0"
    after = det.detect(s, score_threshold=0.3)["targets"]
    assert len(after) == len(before) > 0
    for x, y in zip(before, after):  # (the same graph and threads: only float rounding may differ, on any CPU)
        np.testing.assert_allclose(x["box"], y["box"], rtol=1e-6, atol=1e-3 * s.dt_s)
        assert abs(x["score"] - y["score"]) < 1e-5 and x["apex_trace"] == y["apex_trace"]
    Detector.load().share_cores()  # (the torch engine: nothing to change)


def test_runtime_choice_and_wrong_files(tmp_path):
    assert isinstance(load_detector(), OnnxDetector)  # the shipped model on the CPU: ONNX Runtime
    assert type(load_detector(engine="torch")) is Detector
    assert type(load_detector(DEFAULT_WEIGHTS)) is Detector  # a .pt file: PyTorch
    assert isinstance(load_detector(DEFAULT_ONNX), OnnxDetector)
    with pytest.raises(GPR3DError, match="needs an .onnx file"):
        load_detector(DEFAULT_WEIGHTS, engine="onnx")
    with pytest.raises(GPR3DError, match="ONNX export: run it with --runtime onnx"):
        load_detector(DEFAULT_ONNX, engine="torch")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"\x08\x07junk")
    with pytest.raises(GPR3DError, match="not a readable ONNX detector"):
        load_detector(bad)
    with pytest.raises(GPR3DError, match="unknown engine"):
        load_detector(engine="tensorrt")


def test_detect_with_onnx_runtime_never_imports_torch(tmp_path):
    from gpr3d.core.survey import Survey
    from gpr3d.simulation.surveys import survey_sample

    s, _ = survey_sample(777, 2)
    f = tmp_path / "s.h5"
    Survey.save(s, f)
    code = ("import sys; from gpr3d.cli.main import main; rc = main(['detect', sys.argv[1], '--out', sys.argv[2]]); "
            "assert rc == 0; print('torch' in sys.modules, 'torchvision' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code, str(f), str(tmp_path / "d.json")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "False False"


@pytest.fixture
def fresh_nms(monkeypatch):
    from gpr3d.detection import ort as gort

    monkeypatch.setattr(gort, "_nms_session", None)  # built in the test, not by an earlier one
    return gort


def test_onnx_nms_builds_its_session_and_returns_int64_indices(fresh_nms):
    from torchvision.ops import nms

    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [20, 20, 30, 30]], np.float64)
    scores = np.array([0.5, 0.9, 0.7])
    got = fresh_nms.onnx_nms(boxes, scores, 0.5)
    assert got.dtype == np.int64 and got.tolist() == [1, 2] == nms(torch.as_tensor(boxes), torch.as_tensor(scores),
                                                                    0.5).tolist()
    assert fresh_nms._nms_session.get_providers() == ["CPUExecutionProvider"]
    empty = fresh_nms.onnx_nms(np.zeros((0, 4)), np.zeros(0), 0.5)
    assert empty.dtype == np.int64 and empty.shape == (0,)


def test_onnx_detector_settings_and_messages_in_full(tmp_path, fresh_nms):
    from gpr3d.core.errors import FormatError

    det = OnnxDetector.load(threads=1)
    opts = det.session.get_session_options()
    assert (opts.intra_op_num_threads, opts.log_severity_level) == (1, 3)
    assert det.session.get_providers() == ["CPUExecutionProvider"]
    assert det.path == DEFAULT_ONNX and det.device == "cpu" and det.model is None and det.provenance
    assert OnnxDetector.load().session.get_session_options().intra_op_num_threads == 0  # ONNX Runtime's choice
    im = np.random.default_rng(0).random((3, det.window.rows, det.window.traces)).astype(np.float64)
    (b, s), = det.predict_windows([im])  # float64 images are cast for the graph
    assert b.dtype == np.float64 and s.dtype == np.float64 and b.shape == (s.size, 4)
    cases = [(dict(path=DEFAULT_ONNX, device="cuda"),
              f"{DEFAULT_ONNX.name}: the ONNX engine runs on the CPU; use the torch engine for --device cuda"),
             (dict(path=tmp_path / "absent.onnx"), "absent.onnx: no such ONNX detector file"),
             (dict(path=fresh_nms.NMS_ONNX), "nms.onnx: an ONNX file without gpr3d detector metadata")]
    for kw, msg in cases:
        with pytest.raises(FormatError) as err:
            OnnxDetector.load(**kw)
        assert str(err.value) == msg
    (tmp_path / "junk.onnx").write_bytes(b"not a graph")
    with pytest.raises(FormatError) as err:
        OnnxDetector.load(tmp_path / "junk.onnx")
    text = str(err.value)
    assert text.startswith("junk.onnx: not a readable ONNX detector (") and text.endswith(")")
    assert "None" not in text and len(text.splitlines()) == 1


def test_export_writes_a_graph_with_its_names_metadata_and_pytorch_s_answer(tmp_path):
    import json

    onnx = pytest.importorskip("onnx")
    from gpr3d.detection.ort import OPSET, export_onnx
    from gpr3d.detection.weights import load_weights

    out = tmp_path / "d.onnx"
    info = export_onnx(out=out)
    assert info["file"] == str(out) and info["bytes"] == out.stat().st_size and 0 <= info["max_abs_diff"] < 0.1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.onnx"]  # nothing left beside it
    g = onnx.load(str(out))
    assert [i.name for i in g.graph.input] == ["image"]
    model, _, _ = load_weights()
    kinds = model.gpr3d_kinds
    assert [o.name for o in g.graph.output] == ["boxes", "labels", "scores"] + (["kind_scores", "kind_probs"] if kinds
                                                                             else [])
    assert OPSET == 17 and {o.domain: o.version for o in g.opset_import}[""] == 17
    meta = json.loads({p.key: p.value for p in g.metadata_props}["gpr3d.detector"])
    _, window, prov = load_weights()
    assert meta == {"window": window.to_dict(), "provenance": prov, "source_weights": DEFAULT_WEIGHTS.name,
                    "source_sha256": hashlib.sha256(DEFAULT_WEIGHTS.read_bytes()).hexdigest(), "opset": 17,
                    **({"kinds": kinds} if kinds else {})}
    det = OnnxDetector.load(out)
    assert det.window == window and det.provenance == prov and det.kinds == kinds
    # the graph names the kinds PyTorch names, with the same shares
    im = np.random.default_rng(4).random((3, window.rows, window.traces), dtype=np.float32)
    (b1, s1, l1, k1, p1), = det.predict_windows_kinds([im])
    (b2, s2, l2, k2, p2), = Detector.load().predict_windows_kinds([im])
    # each of the ONNX graph's five best boxes against PyTorch's nearest (near-equal scores may come out in
    # another order on another CPU, so boxes are paired by place, not rank; float16 weights in both: 2e-3)
    for j in np.argsort(-s1)[:5]:
        near = int(np.argmin(np.abs(b2 - b1[j]).max(axis=1)))
        assert np.abs(b2[near] - b1[j]).max() < 0.1 and l2[near] == l1[j] and abs(k2[near] - k1[j]) < 2e-3
        # every kind's share too (a row summing to 1, its best the kind named)
        assert np.abs(p2[near] - p1[j]).max() < 2e-3 and abs(p1[j].sum() - 1) < 1e-5 and np.argmax(p1[j]) == l1[j] - 1
    im = np.random.default_rng(3).random((3, window.rows, window.traces), dtype=np.float32)
    (b, s), = det.predict_windows([im])
    (b0, s0), = Detector.load().predict_windows([im])
    assert b.shape == b0.shape and np.abs(np.sort(s) - np.sort(s0)).max() < 2e-3


def test_an_export_of_calibrated_weights_carries_the_map_and_applies_it(tmp_path):
    from gpr3d.detection.calibration import calibrate
    from gpr3d.detection.ort import export_onnx
    from gpr3d.simulation.surveys import survey_sample

    obj = torch.load(DEFAULT_WEIGHTS, weights_only=True)
    cal = {"method": "platt", "a": 0.8, "b": -1.5}
    obj["provenance"] = {**obj["provenance"], "score_calibration": cal}
    torch.save(obj, tmp_path / "cal.pt")
    export_onnx(tmp_path / "cal.pt", tmp_path / "cal.onnx")
    det = OnnxDetector.load(tmp_path / "cal.onnx")
    assert det.calibration == cal
    s, _ = survey_sample(777, 5)
    got = det.detect(s, score_threshold=0.0)
    raw = OnnxDetector.load().detect(s, score_threshold=0.0)  # the shipped graph: the same network, no map
    assert got["calibrated"] and not raw["calibrated"] and len(got["targets"]) == len(raw["targets"]) > 0
    # (the two exports of one network agree to ONNX Runtime's rounding; the map moves scores by up to ~0.5)
    np.testing.assert_allclose([t["score"] for t in got["targets"]],
                               calibrate([t["score"] for t in raw["targets"]], cal), atol=1e-4)
