"""Data shipped with gpr3d (see ATTRIBUTION.md)."""

from importlib.resources import files

__all__ = ["example_dzt", "example_pgpr"]


def example_dzt():
    """Path of the embedded example recording (GSSI 400 MHz, MIT licence, from GPRPy).

    Returns
    -------
    importlib.resources.abc.Traversable
        ``FILE____032.DZT`` inside the installed package (a path on disk for a normal install).
    """
    return files(__name__) / "FILE____032.DZT"


def example_pgpr():
    """Folder of the embedded real labelled 1.6 GHz B-scan (P-GPR, CC BY 4.0): ``images/`` and ``labels/`` (YOLO).

    Returns
    -------
    importlib.resources.abc.Traversable
        The folder inside the installed package; its ``README.md`` credits the dataset's authors.
    """
    return files(__name__) / "pgpr"
