"""Hyperbola detection in B-scans: windows, torchvision detectors, training, evaluation, inference.

Depends on ``core``, ``io`` and ``processing`` only: training records come from
any source of ``(Survey, labels)`` (the CLI plugs in the survey-scale simulator).
"""

from gpr3d.detection.infer import Detector
from gpr3d.detection.windows import WindowConfig

__all__ = ["Detector", "WindowConfig"]
