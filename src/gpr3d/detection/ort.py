"""Detection without PyTorch at run time: the detector exported to ONNX, run by ONNX Runtime.

Importing PyTorch and torchvision takes seconds (about 4 s here, most of
``gpr3d detect``'s start-up), ONNX Runtime a fifth of one. :func:`export_onnx` turns a
weights file into an ONNX graph (torchvision's detectors export with their
post-processing); :class:`OnnxDetector` runs it with the same windows, merge and
apex rules as :class:`~gpr3d.detection.infer.Detector`, and merges boxes across
windows with ONNX Runtime's own ``NonMaxSuppression``.

The graph stores its weights in float16 (as the ``.pt`` files do) with a cast to
float32 in front of each: the file is half the size, and ONNX Runtime folds the
casts once when the session starts, so it computes in float32 as PyTorch does.
The window settings and the provenance travel in the graph's metadata.

:func:`quantise_onnx` makes the 8-bit graph live mode runs by default (``DEFAULT_INT8``, the ``int8`` engine of
:func:`~gpr3d.detection.infer.load_detector`): the float graph's convolutions and its box head's fully connected
layers quantised by ONNX Runtime's static quantisation, calibrated on detector windows.
"""

from __future__ import annotations

import contextlib
import hashlib
from pathlib import Path

import numpy as np

from gpr3d.core.atomic import atomic_path
from gpr3d.core.deps import require
from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.detection.infer import Detector
from gpr3d.detection.windows import WindowConfig
from gpr3d.io.onnxweights import finish_export

__all__ = ["export_onnx", "merge_levels", "OnnxDetector", "onnx_nms", "nms_graph", "quantise_onnx", "DEFAULT_ONNX",
           "DEFAULT_INT8", "NMS_ONNX", "OPSET", "QUANTISED_OPS"]

DEFAULT_ONNX = Path(__file__).with_name("default_detector.onnx")
DEFAULT_INT8 = Path(__file__).with_name("default_detector_int8.onnx")
#: the operators :func:`quantise_onnx` quantises: every convolution and the box head's two fully connected layers;
#: the region pooling, box decoding and NMS stay in float
QUANTISED_OPS = ("Conv", "Gemm")
OPSET = 17
_META = "gpr3d.detector"


def merge_levels(levels, per_level):
    """The pooled features of every region in its own order: ``per_level[k]`` holds, in their order, those of the
    regions whose ``levels`` entry is ``k``.

    What torchvision's multi-scale RoI pooling does when traced for ONNX, with one gather instead of a scatter per
    level: torchvision's graph scatters each level's ``(n_k, C, 7, 7)`` block into a zeroed ``(n, C, 7, 7)`` one
    with an index tensor of that whole shape, which ONNX Runtime ran in 6-7 ms of the shipped detector's 47 ms a
    window (Intel rocketlake, 2 threads); here only the ``n`` region numbers are scattered. The same numbers, in
    the same places.
    """
    torch = require("torch")
    order = torch.cat([torch.where(levels == k)[0] for k in range(len(per_level))])  # the regions, level by level
    rank = torch.cumsum(torch.ones_like(order), 0) - 1  # 0 .. n - 1 (as a traced graph sizes it)
    row = torch.zeros_like(order).scatter(0, order, rank)  # region i's row in the stacked levels
    return torch.cat(per_level).index_select(0, row)


@contextlib.contextmanager
def _gathered_levels():
    """While exporting: torchvision's pooling merges its levels by :func:`merge_levels`."""
    from torchvision.ops import poolers

    was = poolers._onnx_merge_levels
    poolers._onnx_merge_levels = merge_levels
    try:
        yield
    finally:
        poolers._onnx_merge_levels = was


def export_onnx(weights=None, out=DEFAULT_ONNX) -> dict:
    """Export a detector weights file (default: the shipped one) to ONNX at ``out`` (atomically).

    Needs ``torch``, ``torchvision`` and ``onnx``; returns ``{"file", "bytes", "max_abs_diff"}``,
    the largest difference (pixels) of the exported graph's boxes from PyTorch's on a
    test window (each box against its nearest).
    """
    torch = require("torch")
    require("onnx")  # a one-line hint when missing
    ort = require("onnxruntime")
    from gpr3d.detection.weights import DEFAULT_WEIGHTS, load_weights

    src = Path(weights) if weights is not None else DEFAULT_WEIGHTS
    model, window, prov = load_weights(src)
    model.eval()
    rng = np.random.default_rng(0)
    example = torch.from_numpy(rng.random((3, window.rows, window.traces), dtype=np.float32))
    kinds = getattr(model, "gpr3d_kinds", None)
    meta = {"window": window.to_dict(), "provenance": prov,
            "source_weights": src.name, "source_sha256": hashlib.sha256(src.read_bytes()).hexdigest(),
            "opset": OPSET}
    if kinds:
        meta["kinds"] = kinds
    with atomic_path(out, suffix=".onnx.part") as tmp, _gathered_levels():
        torch.onnx.export(model, ([example],), str(tmp), opset_version=OPSET, input_names=["image"],
                          output_names=["boxes", "labels", "scores"] + (["kind_scores", "kind_probs"] if kinds else []),
                          dynamo=False)
        finish_export(tmp, _META, meta)
        # the graph must give PyTorch's answer (float16 weights in both)
        sess = ort.InferenceSession(str(tmp), providers=["CPUExecutionProvider"])
        got = sess.run(None, {"image": example.numpy()})
        with torch.inference_mode():
            ref = model([example])[0]
        if got[0].shape != tuple(ref["boxes"].shape):
            raise RuntimeError(f"exported graph finds {got[0].shape[0]} boxes, PyTorch {ref['boxes'].shape[0]}")
        rb = ref["boxes"].numpy()
        # near-equal scores may come out in another order: match each box to its nearest
        diff = float(max((np.abs(rb - b).max(axis=1).min() for b in got[0]), default=0.0))
    return {"file": str(out), "bytes": Path(out).stat().st_size, "max_abs_diff": diff}


def quantise_onnx(images, out=DEFAULT_INT8, src=DEFAULT_ONNX, *, reduce_range: bool = True,
                  calibration: str = "", command: str = "") -> dict:
    """An 8-bit version of the ONNX detector graph ``src`` written (atomically) at ``out``.

    ONNX Runtime's static quantisation (QDQ format) of :data:`QUANTISED_OPS`: weights int8 per output channel,
    activations uint8 with ranges calibrated (min-max) on ``images``, detector windows as the network takes
    them (``(3, rows, traces)`` float32). ``reduce_range`` keeps the weights to 7 bits: ONNX Runtime multiplies
    uint8 by int8 with an instruction whose pair sums saturate at 16 bits on x86 CPUs without VNNI (AVX2 only, e.g.
    AMD Zen 3), which 7-bit weights cannot reach. The graph carries ``src``'s gpr3d metadata and, under
    ``quantised``, how it was made (``calibration`` and ``command`` describe the windows and the command line).

    Needs ``onnx`` and ``onnxruntime``; returns ``{"file", "bytes", "windows"}``.
    """
    import json
    import tempfile

    onnx = require("onnx")
    ort = require("onnxruntime")
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    from gpr3d.io.onnxweights import open_session

    images = [np.ascontiguousarray(im, dtype=np.float32) for im in images]
    if not images:
        raise InvalidDataError("quantise_onnx needs at least one calibration window")
    src = Path(src)
    _, meta = open_session(src, _META, "detector")
    rows, traces = meta["window"]["rows"], meta["window"]["traces"]
    for i, im in enumerate(images):
        if im.shape != (3, rows, traces) or not np.isfinite(im).all():
            bad = "" if np.isfinite(im).all() else "non-finite "
            raise InvalidDataError(f"calibration window {i}: {im.shape} {bad}values; the network takes finite "
                                   f"(3, {rows}, {traces}) windows")

    class _Windows(CalibrationDataReader):
        def __init__(self):
            self._it = iter([{"image": im} for im in images])

        def get_next(self):
            return next(self._it, None)

    meta["quantised"] = {"source_graph": src.name, "source_sha256": hashlib.sha256(src.read_bytes()).hexdigest(),
                         "operators": list(QUANTISED_OPS), "weights": "int8 per channel" + (
                             ", 7-bit range" if reduce_range else ""), "activations": "uint8, min-max calibrated",
                         "calibration_windows": len(images), "calibration": calibration, "command": command,
                         "onnxruntime": ort.__version__}
    with tempfile.TemporaryDirectory() as tmp, atomic_path(out, suffix=".onnx.part") as part:
        pre = Path(tmp) / "pre.onnx"
        quant_pre_process(str(src), str(pre), skip_symbolic_shape=True)
        quantize_static(str(pre), str(part), _Windows(), quant_format=QuantFormat.QDQ, per_channel=True,
                        op_types_to_quantize=list(QUANTISED_OPS), activation_type=QuantType.QUInt8,
                        weight_type=QuantType.QInt8, reduce_range=reduce_range)
        proto = onnx.load(str(part))
        del proto.metadata_props[:]  # (the pre-processing's own entries too)
        entry = proto.metadata_props.add()
        entry.key, entry.value = _META, json.dumps(meta)
        onnx.save(proto, str(part))
    return {"file": str(out), "bytes": Path(out).stat().st_size, "windows": len(images)}


def nms_graph():
    """A one-node ONNX graph: NonMaxSuppression over one class (boxes (1, N, 4), scores (1, 1, N))."""
    from onnx import TensorProto, helper

    node = helper.make_node("NonMaxSuppression", ["boxes", "scores", "max_out", "iou"], ["selected"],
                            center_point_box=0)
    graph = helper.make_graph(
        [node], "gpr3d_nms",
        [helper.make_tensor_value_info("boxes", TensorProto.FLOAT, [1, None, 4]),
         helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1, 1, None]),
         helper.make_tensor_value_info("max_out", TensorProto.INT64, [1]),
         helper.make_tensor_value_info("iou", TensorProto.FLOAT, [1])],
        [helper.make_tensor_value_info("selected", TensorProto.INT64, [None, 3])])
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 11)])


NMS_ONNX = Path(__file__).with_name("nms.onnx")
_nms_session = None


def onnx_nms(boxes: np.ndarray, scores: np.ndarray, iou: float) -> np.ndarray:
    """Indices of the boxes ``(n, 4)`` [x0, y0, x1, y1] that survive non-maximum suppression, best first.

    ONNX Runtime's ``NonMaxSuppression`` (boxes overlapping a better one by IoU > ``iou``
    are dropped), as torchvision's ``nms``; the graph ships as ``nms.onnx``.
    """
    global _nms_session
    ort = require("onnxruntime")
    if _nms_session is None:
        _nms_session = ort.InferenceSession(str(NMS_ONNX), providers=["CPUExecutionProvider"])
    b = np.asarray(boxes, dtype=np.float32).reshape(1, -1, 4)
    s = np.asarray(scores, dtype=np.float32).reshape(1, 1, -1)
    if b.shape[1] == 0:
        return np.zeros(0, dtype=np.int64)
    sel = _nms_session.run(None, {"boxes": b, "scores": s, "max_out": np.array([b.shape[1]], dtype=np.int64),
                                  "iou": np.array([iou], dtype=np.float32)})[0]
    return sel[:, 2].astype(np.int64)


class OnnxDetector(Detector):
    """A :class:`~gpr3d.detection.infer.Detector` whose network runs in ONNX Runtime (no PyTorch needed)."""

    nms = staticmethod(onnx_nms)

    def __init__(self, session, window: WindowConfig, *, provenance: dict | None = None, path=None, kinds=None):
        super().__init__(None, window, provenance=provenance, device="cpu")
        self.session, self.path, self._kinds = session, path, kinds

    @property
    def kinds(self) -> list[str] | None:
        return self._kinds

    @classmethod
    def load(cls, path=None, *, device: str = "cpu", threads: int | None = None) -> "OnnxDetector":
        from gpr3d.io.onnxweights import open_session

        p = Path(path) if path is not None else DEFAULT_ONNX
        if str(device) != "cpu":
            raise FormatError(p, f"the ONNX engine runs on the CPU; use the torch engine for --device {device}")
        sess, meta = open_session(p, _META, "detector", threads=threads)
        prov = dict(meta.get("provenance", {}))
        if "quantised" in meta:  # an 8-bit graph (quantise_onnx): its name says so, its making travels with it
            prov["name"] = f"{prov.get('name', 'gpr3d detector')} (8-bit)"
            prov["quantised"] = meta["quantised"]
        return cls(sess, WindowConfig(**meta["window"]), provenance=prov, path=p, kinds=meta.get("kinds"))

    def share_cores(self) -> None:
        """Let the session's threads sleep between runs instead of spinning on the cores (ONNX Runtime's habit):
        live mode runs the migration's threads between windows, and a spinning pool takes cores from them
        (measured in live mode, 80,000 traces at 800/s on 2 cores: 1.42 s behind at the end with the pool
        spinning, 0.27 s with it sleeping; a window's CPU time 103 ms against 77 ms). A lone detector gains
        nothing from it: its windows follow one another."""
        from gpr3d.io.onnxweights import open_session

        self.session, _ = open_session(self.path, _META, "detector", spin=False)

    def predict_windows_kinds(self, images: list[np.ndarray]) -> list[tuple]:
        from gpr3d.detection.infer import _kept

        out = []
        for im in images:
            got = self.session.run(None, {"image": np.ascontiguousarray(im, dtype=np.float32)})
            boxes, labels, scores = got[:3]
            # (kind_probs: a graph exported before it was an output has none)
            out.append(_kept(self.kinds, boxes, scores, labels, got[3] if len(got) > 3 else None,
                             got[4] if len(got) > 4 else None))
        return out
