"""ONNX model files: float16 storage of a graph's weights.

The networks gpr3d ships (the detector, DepthNet) store their weights in float16, as
their ``.pt`` files do, with a cast to float32 in front of each: the file is half the
size, and ONNX Runtime folds the casts once when the session starts, so it computes in
float32 as PyTorch does.
"""

from __future__ import annotations

import numpy as np

__all__ = ["fp16_initializers", "finish_export"]


def fp16_initializers(model_proto):
    """Store float32 initializers as float16, each followed by a Cast back to float32 (in place)."""
    from onnx import TensorProto, helper, numpy_helper

    g = model_proto.graph
    casts, keep = [], []
    for init in g.initializer:
        if init.data_type != TensorProto.FLOAT or int(np.prod(init.dims or [1])) < 16:
            keep.append(init)  # small tensors (shapes, thresholds) stay as they are
            continue
        arr = numpy_helper.to_array(init)
        half = numpy_helper.from_array(arr.astype(np.float16), init.name + "__fp16")
        keep.append(half)
        casts.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT,
                                      name=init.name + "__cast"))
    del g.initializer[:]
    g.initializer.extend(keep)
    nodes = list(g.node)
    del g.node[:]
    g.node.extend(casts + nodes)


def finish_export(path, key: str, meta: dict) -> None:
    """An ONNX file just exported at ``path``: weights to float16, ``meta`` (JSON) under ``key`` in its
    metadata, checked and saved in place."""
    import json

    import onnx

    proto = onnx.load(str(path))
    fp16_initializers(proto)
    del proto.metadata_props[:]
    entry = proto.metadata_props.add()
    entry.key, entry.value = key, json.dumps(meta)
    onnx.checker.check_model(proto)
    onnx.save(proto, str(path))
