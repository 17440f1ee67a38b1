"""3D migration from arbitrary antenna poses, masking, the traditional grid method, target extraction.

The names below are imported on first use: ``gpr3d.migration.config`` (what the command line
reads its defaults from) then costs nothing of numba's or SciPy's start-up.
"""

__all__ = ["Grid3D", "BackProjection", "antenna_positions", "dot_test", "preload_tiled"]


def __getattr__(name):
    if name == "Grid3D":
        from gpr3d.core.grid import Grid3D

        return Grid3D
    if name in ("BackProjection", "antenna_positions", "dot_test"):
        from gpr3d.migration import operator

        return getattr(operator, name)
    if name == "preload_tiled":  # (the back projection's tiled kernel loaded in a thread: a command's first step)
        from gpr3d.migration._kernels import preload_tiled

        return preload_tiled
    raise AttributeError(f"module 'gpr3d.migration' has no attribute {name!r}")
