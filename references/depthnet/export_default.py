"""Make a trained DepthNet the shipped default: ONNX export into the package and its provenance beside it.

    python references/depthnet/export_default.py RUN/depthnet.pt

Writes ``src/gpr3d/inversion/default_depthnet.onnx`` (float16 weights, ONNX Runtime: ``gpr3d detect`` stays free
of PyTorch) and ``default_depthnet.json`` (the training command and data, validation, SHA-256 of both files), and
keeps the ``.pt`` as ``references/depthnet/default_depthnet.pt`` (the package would exceed its 30 MB of weights
with it; fine-tuning and the PyTorch runtime start from it).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main(argv=None):
    import torch

    from gpr3d.inversion.depthnet import export_depthnet_onnx

    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        sys.exit(__doc__)
    src = Path(argv[0])
    pkg = ROOT / "src" / "gpr3d" / "inversion"
    info = export_depthnet_onnx(src, pkg / "default_depthnet.onnx")
    keep = ROOT / "references" / "depthnet" / "default_depthnet.pt"
    shutil.copyfile(src, keep)
    prov = torch.load(src, map_location="cpu", weights_only=True)["provenance"]
    sha = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in (pkg / "default_depthnet.onnx", keep)}
    doc = {"name": "DepthNet resnet10n", "provenance": prov, "onnx": {"bytes": info["bytes"],
                                                                      "max_diff_vs_torch": info["max_diff"]},
           "sha256": sha, "evaluation": "benchmarks/results/depth.md (python benchmarks/eval_depth.py)"}
    (pkg / "default_depthnet.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(json.dumps({"onnx": info, "sha256": sha}, indent=1))


if __name__ == "__main__":
    main()
