"""Detector weight files: the state dict in float16 with what is needed to rebuild and trust it.

A weights file is a ``torch.save`` dict, loaded with ``weights_only=True``::

    {"format": "gpr3d.detector", "version": 1, "model": NAME, "window": {...WindowConfig},
     "state_dict": {...float16 tensors...}, "provenance": {"command", "dataset", "metrics", ...}}

The default weights ship inside the package (``gpr3d/detection/default_detector.pt``)
with their provenance beside them in ``default_detector.json``.
"""

from __future__ import annotations

from pathlib import Path

from gpr3d.core.atomic import atomic_path
from gpr3d.core.deps import require
from gpr3d.core.errors import FormatError
from gpr3d.io.weights import half_state_dict, read_weights_file

__all__ = ["save_weights", "load_weights", "DEFAULT_WEIGHTS"]

FORMAT = "gpr3d.detector"
DEFAULT_WEIGHTS = Path(__file__).with_name("default_detector.pt")


def save_weights(model, name: str, window: dict, path, *, provenance: dict | None = None, kinds=None) -> None:
    """Write ``model``'s weights (float16 for floating tensors) atomically; ``kinds`` the target kinds it names."""
    torch = require("torch")
    obj = {"format": FORMAT, "version": 1, "model": name, "window": dict(window), "state_dict": half_state_dict(model),
           "provenance": provenance or {}}
    if kinds:
        obj["kinds"] = [str(k) for k in kinds]
    with atomic_path(path, suffix=".pt.part") as tmp:
        torch.save(obj, tmp)


def load_weights(path=None, *, device: str = "cpu"):
    """``(model in eval mode, WindowConfig, provenance)`` from a weights file (default: the shipped one).

    The model's ``gpr3d_kinds`` attribute lists the target kinds it names (``None``: one class).
    """
    from gpr3d.detection.models import MODELS, build_model, resolve_device
    from gpr3d.detection.windows import WindowConfig

    dev = resolve_device(device)
    p = Path(path) if path is not None else DEFAULT_WEIGHTS
    obj = read_weights_file(p, FORMAT, "detector")
    name = obj.get("model")
    if name not in MODELS:
        raise FormatError(p, f"unknown model {name!r} in the weights file")
    window = WindowConfig(**obj["window"])
    kinds = obj.get("kinds")
    if kinds is not None and (not isinstance(kinds, list) or not kinds or not all(isinstance(k, str) for k in kinds)):
        raise FormatError(p, f"kinds must be a list of target kinds, got {kinds!r:.80}")
    model = build_model(name, image_size=window.rows, kinds=kinds)
    model.gpr3d_kinds = kinds
    sd = {k: v.float() if v.is_floating_point() else v for k, v in obj["state_dict"].items()}
    try:
        model.load_state_dict(sd)
    except RuntimeError as exc:
        first = str(exc).splitlines()[1].strip() if len(str(exc).splitlines()) > 1 else str(exc)
        raise FormatError(p, f"weights do not fit model {name!r}: {first[:160]}") from None
    model.eval().to(dev)
    return model, window, obj.get("provenance", {})
