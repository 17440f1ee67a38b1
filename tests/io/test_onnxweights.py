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
