"""A pinhole camera's intrinsics (the depth camera of an RGB-D rig)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["CameraIntrinsics"]


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole camera (pixels); :meth:`d435i` gives the D435i's depth stream at 640 x 480 or scaled down."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self):
        if not (int(self.width) == self.width > 1 and int(self.height) == self.height > 1):
            raise InvalidDataError(f"image size must be whole pixels > 1, got {self.width} x {self.height}")
        if not (self.fx > 0 and self.fy > 0 and np.isfinite(self.cx) and np.isfinite(self.cy)):
            raise InvalidDataError(f"focal lengths must be positive pixels, got fx={self.fx!r} fy={self.fy!r}")

    @classmethod
    def d435i(cls, width: int = 640) -> "CameraIntrinsics":
        """The D435i depth stream's nominal pinhole (640 x 480, 87 x 58 deg field of view), scaled to ``width``."""
        s = width / 640.0
        return cls(int(width), int(round(480 * s)), 382.0 * s, 382.0 * s, 319.5 * s, 239.5 * s)

    def as_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy, "cx": self.cx,
                "cy": self.cy}
