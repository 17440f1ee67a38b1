"""Timestamped antenna poses: the :class:`Trajectory` type shared by io, pose, simulation and migration.

Poses are ``world_from_antenna`` (CONVENTIONS.md): ``positions_xyz (n, 3)`` in metres
and ``orientations_quat_wxyz (n, 4)``; ``timestamps_s (n,)`` in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.poses import normalize_quat

__all__ = ["Trajectory"]


@dataclass
class Trajectory:
    """Timestamped 6-DoF poses ``world_from_antenna``."""

    timestamps_s: np.ndarray
    positions_xyz: np.ndarray
    orientations_quat_wxyz: np.ndarray

    def __post_init__(self):
        self.timestamps_s = np.asarray(self.timestamps_s, dtype=float).reshape(-1)
        n = self.timestamps_s.size
        self.positions_xyz = np.asarray(self.positions_xyz, dtype=float).reshape(n, 3)
        q = np.asarray(self.orientations_quat_wxyz, dtype=float).reshape(n, 4)
        if not (np.all(np.isfinite(self.timestamps_s)) and np.all(np.isfinite(self.positions_xyz))):
            raise InvalidDataError("trajectory holds NaN/inf values")
        try:
            self.orientations_quat_wxyz = normalize_quat(q)
        except ValueError as exc:
            raise InvalidDataError(f"trajectory: {exc}") from None

    def __len__(self) -> int:
        return self.timestamps_s.size
