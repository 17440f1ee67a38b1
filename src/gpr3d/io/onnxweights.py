"""ONNX model files: float16 storage of a graph's weights.

The networks gpr3d ships (the detector, DepthNet) store their weights in float16, as
their ``.pt`` files do, with a cast to float32 in front of each: the file is half the
size, and ONNX Runtime folds the casts once when the session starts, so it computes in
float32 as PyTorch does.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gpr3d.core.deps import require
from gpr3d.core.errors import FormatError

__all__ = ["fp16_initializers", "finish_export", "open_session"]


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
    import onnx

    proto = onnx.load(str(path))
    fp16_initializers(proto)
    del proto.metadata_props[:]
    entry = proto.metadata_props.add()
    entry.key, entry.value = key, json.dumps(meta)
    onnx.checker.check_model(proto)
    onnx.save(proto, str(path))


def open_session(path, key: str, what: str, *, threads: int | None = None, spin: bool = True):
    """``(session, meta)``: an ONNX Runtime CPU session on the gpr3d file ``path`` and the JSON it holds
    under ``key``; a missing, unreadable or foreign file is one
    :class:`~gpr3d.core.errors.FormatError` naming ``what``.

    ``threads``: the session's own thread pool (``None``: ONNX Runtime's choice, one per core);
    ``spin=False``: its threads sleep between runs instead of spinning, which leaves the cores
    to other sessions and threads of the same process.
    """
    ort = require("onnxruntime")
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, f"no such ONNX {what} file")
    opts = ort.SessionOptions()
    opts.log_severity_level = 3
    if threads:
        opts.intra_op_num_threads = int(threads)
    if not spin:
        opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    try:
        sess = ort.InferenceSession(str(p), opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # noqa: BLE001 - ORT raises its own exception types
        raise FormatError(p, f"not a readable ONNX {what} ({type(exc).__name__}: "
                             f"{(str(exc).splitlines() or [''])[0][:120]})") from None
    meta = sess.get_modelmeta().custom_metadata_map.get(key)
    if meta is None:
        raise FormatError(p, f"an ONNX file without gpr3d {what} metadata")
    return sess, json.loads(meta)
