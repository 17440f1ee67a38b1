"""Readers and writers: radar formats, gpr3d HDF5, SEG-Y, trajectories."""

from gpr3d.io.registry import FORMATS, detect_format, read, read_all, register

__all__ = ["FORMATS", "detect_format", "read", "read_all", "register"]
