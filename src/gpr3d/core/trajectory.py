"""Timestamped antenna poses: the :class:`Trajectory` type shared by io, pose, simulation and migration.

Poses are ``world_from_antenna`` (CONVENTIONS.md): ``positions_xyz (n, 3)`` in metres
and ``orientations_quat_wxyz (n, 4)``; ``timestamps_s (n,)`` in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.poses import normalize_quat, slerp

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

    def at(self, t_s, *, latency_s: float = 0.0) -> "Trajectory":
        """Poses at times ``t_s`` (linear in position, SLERP in rotation), stamped ``t_s``.

        ``latency_s``: the poses are taken at ``t_s + latency_s`` (a sensor's clock behind the
        trajectory's). Times outside the trajectory's span are an error, not an extrapolation.
        """
        ts = self.timestamps_s
        if ts.size < 2 or np.any(np.diff(ts) <= 0):
            raise InvalidDataError("trajectory timestamps must increase strictly (two poses at least)")
        t_out = np.asarray(t_s, dtype=float).reshape(-1)
        t = t_out + float(latency_s)
        if not np.all(np.isfinite(t)):
            raise InvalidDataError("times to interpolate poses at hold NaN/inf")
        outside = (t < ts[0]) | (t > ts[-1])
        if outside.any():
            raise InvalidDataError(f"{int(outside.sum())} of {t.size} times fall outside the trajectory "
                                   f"[{ts[0]:.3f}, {ts[-1]:.3f}] s (first {t[outside][0]:.3f} s)")
        frac = np.interp(t, ts, np.arange(ts.size))
        i0 = np.minimum(np.floor(frac).astype(int), ts.size - 2)
        w = frac - i0
        pos = self.positions_xyz[i0] * (1 - w[:, None]) + self.positions_xyz[i0 + 1] * w[:, None]
        q = slerp(self.orientations_quat_wxyz[i0], self.orientations_quat_wxyz[i0 + 1], w)
        return Trajectory(t_out, pos, q)

    def path_length_m(self) -> np.ndarray:
        """Cumulative length of the path through the positions, from 0 at the first pose."""
        steps = np.linalg.norm(np.diff(self.positions_xyz, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])
