"""Data shipped with gpr3d (see ATTRIBUTION.md)."""

from importlib.resources import files

__all__ = ["example_dzt"]


def example_dzt():
    """Path of the embedded example recording (GSSI 400 MHz, MIT licence, from GPRPy)."""
    return files(__name__) / "FILE____032.DZT"
