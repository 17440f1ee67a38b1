"""3D migration from arbitrary antenna poses, masking, the traditional grid method, target extraction."""

from gpr3d.core.grid import Grid3D
from gpr3d.migration.operator import BackProjection, antenna_positions, dot_test

__all__ = ["Grid3D", "BackProjection", "antenna_positions", "dot_test"]
