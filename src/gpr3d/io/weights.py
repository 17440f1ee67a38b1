"""gpr3d's network weight files (``torch.save`` dicts, read with ``weights_only=True``): float16 state dicts
and the checks every reader makes before it builds a model."""

from __future__ import annotations

from pathlib import Path

from gpr3d.core.deps import require
from gpr3d.core.errors import FormatError

__all__ = ["half_state_dict", "read_weights_file"]


def half_state_dict(model) -> dict:
    """The model's state dict on the CPU, floating tensors in float16."""
    return {k: (v.detach().half() if v.is_floating_point() else v.detach()).cpu() for k, v in model.state_dict().items()}


def read_weights_file(path, fmt: str, what: str) -> dict:
    """The dict of a weights file whose ``"format"`` is ``fmt`` and ``"version"`` 1, or a one-line
    :class:`~gpr3d.core.errors.FormatError` (``what`` names the kind of file: "detector", "DepthNet")."""
    torch = require("torch")
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, f"no such {what} weights file")
    try:
        obj = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many kinds for a bad file
        raise FormatError(p, f"not a readable weights file ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0][:120] if str(exc) else ''})") from None
    if not isinstance(obj, dict) or obj.get("format") != fmt:
        raise FormatError(p, f"not a gpr3d {what} weights file")
    if obj.get("version") != 1:
        raise FormatError(p, f"{what} weights version {obj.get('version')!r} is not supported (expected 1)")
    return obj
