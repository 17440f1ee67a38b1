"""gpr3d: find and reconstruct buried objects in 3D from ground-penetrating radar.

>>> import gpr3d
>>> survey = gpr3d.read("FILE____032.DZT")          # doctest: +SKIP
>>> survey.time_zero().dewow().remove_background()  # doctest: +SKIP
"""

__version__ = "0.1.0"

from gpr3d.core.errors import (  # noqa: E402
           FormatError,
           GPR3DError,
           InvalidDataError,
           TruncatedRecordingWarning,
)
from gpr3d.core.survey import Survey, register_plugin  # noqa: E402
from gpr3d.io.registry import read, read_all  # noqa: E402

# the data model's file and processing methods, wired here above the floors they come from (core imports neither);
# the steps by name, so that scipy is imported only when a survey is first processed
register_plugin("save", "gpr3d.io.hdf5:write_survey")
register_plugin("load", "gpr3d.io.hdf5:read_survey")
register_plugin("step", "gpr3d.processing.steps:run_step")

__all__ = ["__version__", "Survey", "read", "read_all", "GPR3DError", "FormatError", "InvalidDataError",
           "TruncatedRecordingWarning"]
