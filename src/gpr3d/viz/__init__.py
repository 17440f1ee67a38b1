"""Figures: B-scans (with boxes), later migrated slices and 3D views."""

from gpr3d.viz.bscan import plot_bscan, save_bscan_png

__all__ = ["plot_bscan", "save_bscan_png"]
