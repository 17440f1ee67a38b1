"""Voxel grids: :class:`gpr3d.core.grid.Grid3D` (a core type: the volume files in :mod:`gpr3d.io.volume` use it
too), importable from here as well."""

from gpr3d.core.grid import Grid3D

__all__ = ["Grid3D"]
