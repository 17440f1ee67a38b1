"""Optional dependencies: one place that imports them and says how to install them.

Heavy parts of gpr3d live in extras (``pip install 'gpr3d[sim]'`` and so on).
:func:`require` imports a module or raises :class:`MissingDependencyError` with a
one-line install hint.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from gpr3d.core.errors import GPR3DError, InvalidDataError, MissingDependencyError

__all__ = ["EXTRAS", "require", "available", "resolve_device"]

#: module name -> (pip extra, what it is used for)
EXTRAS: dict[str, tuple[str, str]] = {
    "gprMax": ("sim", "FDTD simulation of GPR scenes"),
    "torch": ("dl", "detection and DepthNet networks"),
    "torchvision": ("dl", "detection networks"),
    "open3d": ("rgbd", "RGB-D visual odometry"),
    "evo": ("pose", "trajectory metrics"),
    "dask": ("scale", "parallel dataset building"),
    "distributed": ("scale", "parallel dataset building"),
    "readgssi": ("bench", "the reference DZT reader in benchmarks"),
    "segyio": ("", "SEG-Y export"),
}


def available(module: str) -> bool:
    """True if ``module`` can be imported."""
    try:
        importlib.import_module(module)
    except Exception:  # noqa: BLE001 - a broken install is as good as absent
        return False
    return True


def require(module: str) -> ModuleType:
    """Import ``module`` or raise :class:`MissingDependencyError` with an install hint."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        extra, purpose = EXTRAS.get(module, ("", ""))
        target = f"'gpr3d[{extra}]'" if extra else module
        why = f" (needed for {purpose})" if purpose else ""
        raise MissingDependencyError(
            f"{module} is not installed{why}: pip install {target}"
        ) from exc


def resolve_device(name: str):
    """``torch.device`` for ``cpu``, ``cuda``, ``cuda:N`` or ``mps``, or a one-line error."""
    torch = require("torch")
    ok = name in ("cpu", "cuda", "mps") or (name.startswith("cuda:") and name[5:].isdigit())
    if not ok:
        raise InvalidDataError(f"--device must be cpu, cuda, cuda:N or mps, got {name!r}")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise GPR3DError(f"--device {name}: CUDA is not available on this machine (use --device cpu)")
    if name == "mps" and not torch.backends.mps.is_available():
        raise GPR3DError("--device mps: MPS is not available on this machine (use --device cpu)")
    return torch.device(name)
