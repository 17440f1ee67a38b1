"""Amplitude gains: t-power, spreading and exponential compensation (SEC), AGC.

Gains act on two-way time ``t - t0`` and leave samples before time zero unchanged.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

__all__ = ["gain_curve_sec", "gain_tpow", "gain_sec", "gain_agc"]


def gain_curve_sec(
    n_samples: int,
    dt_s: float,
    *,
    alpha_per_s: float = 0.0,
    power: float = 0.0,
    t0_s: float = 0.0,
    t_ref_s: float = 1e-9,
    max_gain: float | None = None,
) -> np.ndarray:
    """Gain ``g(t) = (t'/t_ref)^power * exp(alpha * t')`` with ``t' = max(t - t0, 0)``.

    Where ``t' < t_ref`` the power term is held at 1 so early samples are never attenuated.

    Parameters
    ----------
    n_samples : int
        Samples per trace.
    dt_s : float
        Sample interval (s).
    alpha_per_s : float
        Exponential rate (1/s).
    power : float
        Spreading exponent.
    t0_s : float
        Time zero (s after the first sample).
    t_ref_s : float
        Reference time of the power term (s).
    max_gain : float, optional
        Caps the curve.

    Returns
    -------
    ndarray
        ``(n_samples,)`` float64 gain per sample.
    """
    t = np.arange(n_samples) * dt_s - t0_s
    tp = np.maximum(t, 0.0)
    g = np.maximum(tp / t_ref_s, 1.0) ** power * np.exp(alpha_per_s * tp)
    if max_gain is not None:
        g = np.minimum(g, max_gain)
    return g


def gain_tpow(
    data: np.ndarray, dt_s: float, *, power: float = 1.0, t0_s: float = 0.0, t_ref_s: float = 1e-9
) -> np.ndarray:
    """Multiply every trace by ``((t - t0) / t_ref)^power`` (geometric spreading).

    Parameters
    ----------
    data, dt_s : (n_traces, n_samples) array, float
        The B-scan and its sample interval (s).
    power : float
        The exponent.
    t0_s : float
        Time zero (s after the first sample).
    t_ref_s : float
        Reference time (s): the gain is held at 1 before it.

    Returns
    -------
    ndarray
        The traces times the gain, float32, as ``data``.
    """
    g = gain_curve_sec(np.shape(data)[1], dt_s, power=power, t0_s=t0_s, t_ref_s=t_ref_s)
    return (np.asarray(data, dtype=np.float32) * g[None, :]).astype(np.float32)


def gain_sec(
    data: np.ndarray,
    dt_s: float,
    *,
    alpha_per_s: float,
    power: float = 1.0,
    t0_s: float = 0.0,
    t_ref_s: float = 1e-9,
    max_gain: float | None = 1e6,
) -> np.ndarray:
    """Spreading and exponential compensation: :func:`gain_curve_sec` applied to every trace.

    ``alpha_per_s`` is the amplitude attenuation rate in time (1/s). In a medium with attenuation ``a`` (Np/m) and
    speed ``v`` the wave travels ``v t'`` metres in two-way time ``t'``, so ``alpha = a * v``.

    Parameters
    ----------
    data, dt_s : (n_traces, n_samples) array, float
        The B-scan and its sample interval (s).
    alpha_per_s, power, t0_s, t_ref_s, max_gain : float
        The curve's parameters (see :func:`gain_curve_sec`).

    Returns
    -------
    ndarray
        The compensated traces, float32, as ``data``.
    """
    g = gain_curve_sec(
        np.shape(data)[1], dt_s, alpha_per_s=alpha_per_s, power=power, t0_s=t0_s,
        t_ref_s=t_ref_s, max_gain=max_gain,
    )
    return (np.asarray(data, dtype=np.float32) * g[None, :]).astype(np.float32)


def gain_agc(data: np.ndarray, dt_s: float, *, window_s: float, eps: float = 1e-3) -> np.ndarray:
    """Automatic gain control: divide by the RMS amplitude in a centred sliding window.

    Parameters
    ----------
    data, dt_s : (n_traces, n_samples) array, float
        The B-scan and its sample interval (s).
    window_s : float
        The window's length (s).
    eps : float
        Added to the window's RMS, relative to the whole survey's RMS: keeps silent stretches from blowing up.

    Returns
    -------
    ndarray
        The gained traces, float32, as ``data``.
    """
    n = max(int(round(window_s / dt_s)), 1)
    x = np.asarray(data, dtype=np.float64)
    # the running sum can dip a hair below zero in floating point: clamp before the root
    rms = np.sqrt(np.maximum(uniform_filter1d(x * x, size=n, axis=1, mode="nearest"), 0.0))
    floor = eps * np.sqrt(np.mean(x * x))
    if floor == 0:
        return np.asarray(data, dtype=np.float32).copy()
    return (x / np.maximum(rms, floor)).astype(np.float32)
