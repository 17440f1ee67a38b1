"""The project's own exception and warning types.

Every problem a user can cause (a bad file, a wrong argument, a missing optional
dependency) is raised as a :class:`GPR3DError` subclass, so that callers (and the
CLI, which prints them as one line) can tell user errors from bugs.
"""

from __future__ import annotations

import os

__all__ = [
    "GPR3DError",
    "FormatError",
    "UnknownFormatError",
    "InvalidDataError",
    "MissingDependencyError",
    "TruncatedRecordingWarning",
]


class GPR3DError(Exception):
    """Base class of every error gpr3d raises on purpose."""


class FormatError(GPR3DError, ValueError):
    """A file is not what its reader expects (corrupt, truncated, inconsistent).

    The message always starts with the file name, then says what is wrong.
    """

    def __init__(self, path: str | os.PathLike | None, problem: str):
        self.path = None if path is None else os.fspath(path)
        self.problem = problem
        where = f"{os.path.basename(self.path)}: " if self.path else ""
        super().__init__(f"{where}{problem}")


class UnknownFormatError(FormatError):
    """No registered reader recognises the file."""


class InvalidDataError(GPR3DError, ValueError):
    """Arrays or arguments that cannot make a valid survey (shape, NaN, units)."""


class MissingDependencyError(GPR3DError, ImportError):
    """An optional dependency is not installed; the message says how to install it."""


class TruncatedRecordingWarning(UserWarning):
    """A recording ends mid-trace; the partial trace(s) were dropped."""


class GeometryWarning(UserWarning):
    """The survey's geometry cannot support what was asked of it (e.g. 3D from one straight profile)."""
