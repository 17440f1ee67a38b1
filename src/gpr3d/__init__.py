"""gpr3d: find and reconstruct buried objects in 3D from ground-penetrating radar.

>>> import gpr3d
>>> survey = gpr3d.read("FILE____032.DZT")          # doctest: +SKIP
>>> survey.time_zero().dewow().remove_background()  # doctest: +SKIP
"""

__version__ = "0.1.0"

from gpr3d.core.errors import FormatError, GPR3DError, InvalidDataError, TruncatedRecordingWarning  # noqa: E402
from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.io.registry import read, read_all  # noqa: E402

__all__ = ["__version__", "Survey", "read", "read_all", "GPR3DError", "FormatError", "InvalidDataError",
           "TruncatedRecordingWarning"]
