"""Voxel grids for 3D images. Depth is positive downwards below the surface (z = 0)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Grid3D", "CScan"]


@dataclass(frozen=True)
class Grid3D:
    """A regular grid: ``x_i = x0 + i dx``, ``y_j = y0 + j dy``, ``depth_k = d0 + k dd`` (metres).

    Images on it are float32 arrays of shape ``(nx, ny, nd)``.
    """

    x0: float
    y0: float
    d0: float
    dx: float
    dy: float
    dd: float
    nx: int
    ny: int
    nd: int

    @classmethod
    def covering(cls, positions_xyz, *, depth_m: float, spacing_m: float, depth_spacing_m: float | None = None,
                 pad_m: float = 0.0, d0: float | None = None, lattice: bool = False) -> "Grid3D":
        """A grid over the horizontal extent of ``positions_xyz`` (plus ``pad_m``) down to ``depth_m``; with
        ``lattice`` its corner is rounded down to whole multiples of ``spacing_m`` (``x0 = i * spacing_m``) and it
        reaches at least as far."""
        p = np.asarray(positions_xyz, float)
        lo = p[:, :2].min(axis=0) - pad_m
        hi = p[:, :2].max(axis=0) + pad_m
        dd = depth_spacing_m or spacing_m
        start = dd if d0 is None else d0
        if lattice:
            first = np.floor(lo / spacing_m).astype(int)
            last = np.ceil(hi / spacing_m).astype(int)
            return cls(float(first[0] * spacing_m), float(first[1] * spacing_m), float(start), spacing_m, spacing_m,
                       dd, int(last[0] - first[0]) + 1, int(last[1] - first[1]) + 1,
                       int(np.floor((depth_m - start) / dd)) + 1)
        n = np.floor((hi - lo) / spacing_m).astype(int) + 1
        nd = int(np.floor((depth_m - start) / dd)) + 1
        return cls(float(lo[0]), float(lo[1]), float(start), spacing_m, spacing_m, dd, int(n[0]), int(n[1]), nd)

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.nx, self.ny, self.nd)

    @property
    def size(self) -> int:
        return self.nx * self.ny * self.nd

    @property
    def x(self) -> np.ndarray:
        return self.x0 + self.dx * np.arange(self.nx)

    @property
    def y(self) -> np.ndarray:
        return self.y0 + self.dy * np.arange(self.ny)

    @property
    def depth(self) -> np.ndarray:
        return self.d0 + self.dd * np.arange(self.nd)

    def points(self, idx) -> np.ndarray:
        """World coordinates ``(n, 3)`` (z = -depth) of voxel indices ``(n, 3)``."""
        i = np.asarray(idx, float)
        return np.stack([self.x0 + i[:, 0] * self.dx, self.y0 + i[:, 1] * self.dy, -(self.d0 + i[:, 2] * self.dd)],
                        axis=1)

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict) -> "Grid3D":
        """The grid of :meth:`to_dict`'s output, checked: positive steps and counts, finite origins."""
        from gpr3d.core.errors import InvalidDataError

        names = ("x0", "y0", "d0", "dx", "dy", "dd", "nx", "ny", "nd")
        if not isinstance(d, dict) or any(k not in d for k in names):
            raise InvalidDataError(f"a grid needs {', '.join(names)}; got {sorted(d) if isinstance(d, dict) else d!r}")
        try:
            vals = {k: float(d[k]) for k in names[:6]} | {k: int(d[k]) for k in names[6:]}
        except (TypeError, ValueError):
            raise InvalidDataError(f"grid values must be numbers, got {d!r}") from None
        if not all(np.isfinite(vals[k]) for k in names[:6]) or min(vals[k] for k in ("dx", "dy", "dd")) <= 0 \
                or min(vals[k] for k in ("nx", "ny", "nd")) < 1:
            raise InvalidDataError(f"grid steps and counts must be positive and finite, got {d!r}")
        return cls(**vals)


@dataclass
class CScan:
    """Horizontal slices of a survey's envelope on a square grid in the site frame (see
    :mod:`gpr3d.processing.cscan`)."""

    values: np.ndarray  #: (n_slices, nx, ny) float32, NaN where no trace is near
    x0: float  #: centre of cell [0, 0] in the site frame (m)
    y0: float
    cell_m: float
    t_start_s: np.ndarray  #: each slice's window start (two-way time after time zero)
    window_s: float
    depth_m: np.ndarray | None = None  #: each slice's mid depth, with ``eps_r``
    eps_r: float | None = None

    @property
    def x(self) -> np.ndarray:
        return self.x0 + self.cell_m * np.arange(self.values.shape[1])

    @property
    def y(self) -> np.ndarray:
        return self.y0 + self.cell_m * np.arange(self.values.shape[2])
