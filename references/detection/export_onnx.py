"""Export a detector weights file to ONNX (and the merge step's NMS graph) for the torch-free engine.

    python references/detection/export_onnx.py                       # the shipped model -> package
    python references/detection/export_onnx.py WEIGHTS.pt OUT.onnx  # your own weights

Needs torch, torchvision and onnx (the ``dl`` extra). The shipped
``src/gpr3d/detection/default_detector.onnx`` and ``nms.onnx`` are made by the first form.
"""

from __future__ import annotations

import argparse
import json

from gpr3d.detection.ort import DEFAULT_ONNX, NMS_ONNX, nms_graph, export_onnx


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("weights", nargs="?", default=None, help="weights .pt (default: the shipped one)")
    p.add_argument("out", nargs="?", default=str(DEFAULT_ONNX), help="output .onnx (default: into the package)")
    args = p.parse_args(argv)
    import onnx

    onnx.save(nms_graph(), str(NMS_ONNX))
    print(json.dumps(export_onnx(args.weights, args.out)))


if __name__ == "__main__":
    main()
