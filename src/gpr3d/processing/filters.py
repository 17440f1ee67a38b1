"""Zero-phase frequency filters."""

from __future__ import annotations

import numpy as np

__all__ = ["bandpass"]


def bandpass(
    data: np.ndarray,
    dt_s: float,
    *,
    fmin_hz: float | None = None,
    fmax_hz: float | None = None,
    order: int = 4,
) -> np.ndarray:
    """Zero-phase Butterworth filter along time (forward-backward, so the order doubles).

    Give both corners for a band-pass, only ``fmin_hz`` for a high-pass, only ``fmax_hz`` for a low-pass.

    Parameters
    ----------
    data, dt_s : (n_traces, n_samples) array, float
        The B-scan and its sample interval (s).
    fmin_hz, fmax_hz : float, optional
        The corners (Hz), between the lowest frequency the trace length resolves and Nyquist.
    order : int
        The Butterworth order of each pass.

    Returns
    -------
    ndarray
        The filtered traces, float32, as ``data``.

    Raises
    ------
    ValueError
        No corner, a corner outside the resolvable band, ``fmin_hz >= fmax_hz``, or traces too short for the order.
    """
    fs = 1.0 / dt_s
    nyq = fs / 2
    x = np.asarray(data, dtype=np.float64)
    # the lowest frequency a trace holds: a corner below it acts on nothing the record can show, and a Butterworth
    # filter that far below the sampling rate is numerically meaningless (a wrong unit, e.g. MHz given as Hz)
    lowest = 1.0 / (x.shape[1] * dt_s)
    for name, f in (("fmin_hz", fmin_hz), ("fmax_hz", fmax_hz)):
        if f is not None and not lowest <= f < nyq:
            raise ValueError(f"{name} = {f:g} Hz must lie between the lowest frequency the {x.shape[1]}-sample "
                             f"traces hold ({lowest:g} Hz) and the Nyquist frequency {nyq:g} Hz")
    if fmin_hz is None and fmax_hz is None:
        raise ValueError("give fmin_hz, fmax_hz or both")
    from scipy.signal import butter, sosfiltfilt  # (here: scipy.signal is slow to import)

    if fmin_hz is not None and fmax_hz is not None:
        if fmin_hz >= fmax_hz:
            raise ValueError(f"fmin_hz ({fmin_hz:g}) must be below fmax_hz ({fmax_hz:g})")
        sos = butter(order, [fmin_hz, fmax_hz], btype="bandpass", fs=fs, output="sos")
    elif fmin_hz is not None:
        sos = butter(order, fmin_hz, btype="highpass", fs=fs, output="sos")
    else:
        sos = butter(order, fmax_hz, btype="lowpass", fs=fs, output="sos")
    if x.shape[1] <= 3 * (2 * sos.shape[0] + 1):
        raise ValueError(f"traces of {x.shape[1]} samples are too short for an order-{order} filter")
    return sosfiltfilt(sos, x, axis=1).astype(np.float32)
