"""ONNX weights stored in float16: the graph computes with the rounded weights, small tensors stay as they are."""

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")


def test_fp16_initializers_halve_the_weights_and_keep_the_answer():
    from onnx import TensorProto, helper, numpy_helper

    from gpr3d.io.onnxweights import fp16_initializers

    rng = np.random.default_rng(0)
    w = rng.normal(size=(8, 8)).astype(np.float32)
    b = np.array([0.1, 0.2, 0.3], np.float32)  # too small to convert (shapes, thresholds)
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["x", "w"], ["y"])], "g",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 8])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 8])],
        [numpy_helper.from_array(w, "w"), numpy_helper.from_array(b, "b")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    fp16_initializers(model)
    onnx.checker.check_model(model)
    kinds = {i.name: i.data_type for i in model.graph.initializer}
    assert kinds == {"w__fp16": TensorProto.FLOAT16, "b": TensorProto.FLOAT}
    assert model.graph.node[0].op_type == "Cast"  # the cast back runs first
    x = rng.normal(size=(1, 8)).astype(np.float32)
    sess = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    got = sess.run(None, {"x": x})[0]
    np.testing.assert_allclose(got, x @ w.astype(np.float16).astype(np.float32), rtol=1e-5, atol=1e-6)
    assert not np.allclose(got, x @ w, rtol=1e-7, atol=0)  # the rounding is really there


def _graph(inits, nodes=None):
    from onnx import TensorProto, helper

    nodes = nodes or [helper.make_node("MatMul", ["x", "w"], ["y"])]
    return helper.make_model(helper.make_graph(
        nodes, "g", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4])], inits),
        opset_imports=[helper.make_opsetid("", 17)])


def test_only_float32_tensors_of_16_values_or_more_are_halved():
    from onnx import TensorProto, numpy_helper

    from gpr3d.io.onnxweights import fp16_initializers

    w = np.arange(16, dtype=np.float32).reshape(4, 4) / 7  # 16 values: halved
    inits = [numpy_helper.from_array(w, "w"),
             numpy_helper.from_array(np.ones(15, np.float32), "fifteen"),  # one short: kept
             numpy_helper.from_array(np.float32(2.5), "scalar"),  # no dims: one value, kept
             numpy_helper.from_array(np.arange(20, dtype=np.int64), "ints"),  # not float32: kept
             numpy_helper.from_array(np.ones(32, np.float64), "doubles")]
    model = _graph(inits)
    fp16_initializers(model)
    kinds = {i.name: i.data_type for i in model.graph.initializer}
    assert kinds == {"w__fp16": TensorProto.FLOAT16, "fifteen": TensorProto.FLOAT, "scalar": TensorProto.FLOAT,
                     "ints": TensorProto.INT64, "doubles": TensorProto.DOUBLE}
    assert [i.name for i in model.graph.initializer] == ["w__fp16", "fifteen", "scalar", "ints", "doubles"]
    np.testing.assert_array_equal(numpy_helper.to_array(model.graph.initializer[0]), w.astype(np.float16))
    cast, matmul = model.graph.node
    assert (cast.op_type, list(cast.input), list(cast.output), cast.name) == ("Cast", ["w__fp16"], ["w"], "w__cast")
    assert cast.attribute[0].name == "to" and cast.attribute[0].i == TensorProto.FLOAT
    assert matmul.op_type == "MatMul"


def test_finish_export_halves_the_weights_and_leaves_only_our_metadata(tmp_path):
    import json

    from onnx import numpy_helper

    from gpr3d.io.onnxweights import finish_export

    w = (np.arange(16, dtype=np.float32).reshape(4, 4) - 5) / 3
    model = _graph([numpy_helper.from_array(w, "w")])
    old = model.metadata_props.add()
    old.key, old.value = "exporter", "something else"
    path = tmp_path / "m.onnx"
    onnx.save(model, str(path))
    finish_export(path, "gpr3d_meta", {"arch": "tiny", "n": 2})
    back = onnx.load(str(path))
    assert [(m.key, json.loads(m.value)) for m in back.metadata_props] == [("gpr3d_meta", {"arch": "tiny", "n": 2})]
    assert [i.name for i in back.graph.initializer] == ["w__fp16"]
    x = np.array([[1.0, -2.0, 0.5, 3.0]], np.float32)
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    np.testing.assert_allclose(sess.run(None, {"x": x})[0], x @ w.astype(np.float16).astype(np.float32), rtol=1e-6)


def test_finish_export_checks_the_model_before_it_writes(tmp_path):
    from onnx import helper, numpy_helper

    from gpr3d.io.onnxweights import finish_export

    w = np.ones((4, 4), np.float32)
    broken = _graph([numpy_helper.from_array(w, "w")], [helper.make_node("MatMul", ["x", "nowhere"], ["y"])])
    path = tmp_path / "m.onnx"
    onnx.save(broken, str(path))
    before = path.read_bytes()
    with pytest.raises(onnx.checker.ValidationError, match="nowhere"):
        finish_export(path, "gpr3d_meta", {})
    assert path.read_bytes() == before  # left as it was


def test_open_session_returns_the_metadata_and_sets_the_thread_pool(tmp_path):
    from onnx import numpy_helper

    from gpr3d.io.onnxweights import finish_export, open_session

    path = tmp_path / "m.onnx"
    w = np.eye(4, dtype=np.float32) * 2
    onnx.save(_graph([numpy_helper.from_array(w, "w")]), str(path))
    finish_export(path, "gpr3d_meta", {"kind": "test", "n": 3})
    sess, meta = open_session(path, "gpr3d_meta", "thing")
    assert meta == {"kind": "test", "n": 3}
    x = np.array([[1.0, -2.0, 0.5, 3.0]], np.float32)
    np.testing.assert_allclose(sess.run(None, {"x": x})[0], 2 * x)
    opts = sess.get_session_options()
    assert opts.intra_op_num_threads == 0  # ONNX Runtime's own choice
    try:  # no entry: ONNX Runtime raises (or, in some versions, answers empty)
        spinning = opts.get_session_config_entry("session.intra_op.allow_spinning")
    except Exception:  # noqa: BLE001 - ORT's own error type
        spinning = None
    assert spinning != "0"
    quiet, _ = open_session(path, "gpr3d_meta", "thing", threads=1, spin=False)
    opts = quiet.get_session_options()
    assert opts.intra_op_num_threads == 1
    assert opts.get_session_config_entry("session.intra_op.allow_spinning") == "0"
    assert opts.log_severity_level == 3


def test_open_session_names_the_file_and_what_it_should_hold(tmp_path):
    from gpr3d.core.errors import FormatError
    from gpr3d.io.onnxweights import finish_export, open_session

    with pytest.raises(FormatError) as err:
        open_session(tmp_path / "gone.onnx", "k", "widget")
    assert str(err.value) == "gone.onnx: no such ONNX widget file"
    (tmp_path / "junk.onnx").write_bytes(b"not onnx")
    with pytest.raises(FormatError) as err:
        open_session(tmp_path / "junk.onnx", "k", "widget")
    with pytest.raises(Exception) as direct:  # noqa: B017
        ort.InferenceSession(str(tmp_path / "junk.onnx"), providers=["CPUExecutionProvider"])
    first = str(direct.value).splitlines()[0][:120]
    assert str(err.value) == f"junk.onnx: not a readable ONNX widget ({type(direct.value).__name__}: {first})"
    from onnx import numpy_helper

    path = tmp_path / "other.onnx"
    onnx.save(_graph([numpy_helper.from_array(np.eye(4, dtype=np.float32), "w")]), str(path))
    finish_export(path, "someone_else", {})
    with pytest.raises(FormatError) as err:
        open_session(path, "k", "widget")
    assert str(err.value) == "other.onnx: an ONNX file without gpr3d widget metadata"
