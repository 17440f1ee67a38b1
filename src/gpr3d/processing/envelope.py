"""Instantaneous amplitude."""

from __future__ import annotations

import numpy as np
from scipy.signal import hilbert

__all__ = ["envelope"]


def envelope(data: np.ndarray) -> np.ndarray:
    """Magnitude of the analytic signal of each trace (Hilbert transform along time)."""
    return np.abs(hilbert(np.asarray(data, dtype=np.float64), axis=1)).astype(np.float32)
