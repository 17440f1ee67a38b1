"""Plain-Python conversion of numpy values, for JSON outputs and processing history."""

from __future__ import annotations

import numpy as np

__all__ = ["jsonable"]


def jsonable(value):
    """Convert numpy scalars/arrays inside ``value`` to plain Python for JSON."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
