"""Instantaneous amplitude."""

from __future__ import annotations

import numpy as np

from gpr3d.processing.analytic import hilbert_envelope

__all__ = ["envelope"]


def envelope(data: np.ndarray) -> np.ndarray:
    """Magnitude of the analytic signal of each trace (Hilbert transform along time).

    Parameters
    ----------
    data : (n_traces, n_samples) array
        The B-scan.

    Returns
    -------
    ndarray
        The envelope, float32, >= 0, as ``data``.
    """
    # (the analytic signal on NumPy's FFT, as scipy.signal.hilbert makes it: scipy.signal takes a second to import)
    return hilbert_envelope(np.asarray(data, dtype=np.float64), axis=1).astype(np.float32)
