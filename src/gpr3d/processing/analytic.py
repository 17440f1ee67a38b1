"""Two array operations the detector's path needs, on NumPy alone.

``scipy.signal`` (with the ``scipy.stats`` it pulls in) and ``scipy.ndimage`` take about
1.3 s to import on a 2-core host, a third of what ``gpr3d detect`` on a 1040-trace record
costs with start-up. The detector's windows, their image channels and the hyperbola
fits need only an envelope and a running mean, so they use these instead; each equals
its SciPy counterpart to rounding (``tests/processing/test_analytic.py`` compares them).

:func:`analytic` is the analytic signal by the FFT (the spectrum's negative
frequencies zeroed, the positive ones doubled; the DC and Nyquist bins kept), as
``scipy.signal.hilbert`` makes it; :func:`running_mean` is a centred moving average
whose window runs past the ends onto copies of the end samples, as
``scipy.ndimage.uniform_filter1d(..., mode="nearest")`` does.
"""

from __future__ import annotations

import numpy as np

__all__ = ["analytic", "fast_length", "hilbert_envelope", "running_mean"]


def fast_length(m: int) -> int:
    """The smallest length >= ``m`` with no prime factor above 5 (where the FFT is fastest)."""
    m = max(int(m), 1)
    best = None
    p5 = 1
    while p5 < 2 * m:
        p35 = p5
        while p35 < 2 * m:
            k = p35
            while k < m:
                k *= 2
            best = k if best is None else min(best, k)
            p35 *= 3
        p5 *= 5
    return best


def _real_samples(x, axis: int, n: int | None):
    """``x`` as float32 (kept) or float64, its length along ``axis`` and the FFT's length (checked)."""
    x = np.asarray(x)
    if np.iscomplexobj(x):
        raise ValueError("the analytic signal is made from real samples")
    if x.dtype != np.float32:
        x = x.astype(np.float64)
    m = x.shape[axis]
    if m < 1:
        raise ValueError("the analytic signal needs at least one sample along its axis")
    if n is None:
        n = m
    elif n < m:
        raise ValueError(f"the FFT's length {n} is shorter than the {m} samples")
    return x, m, n


def analytic(x, axis: int = -1, n: int | None = None) -> np.ndarray:
    """Analytic signal of real ``x`` along ``axis`` (complex; float32 input stays single precision).

    ``n``: the FFT's length, at least the samples': the samples are followed by zeros up to it and the result is
    cut back to their length, so that the transform does not wrap one end of the axis onto the other (``2 x`` the
    samples rules it out; ``scipy.signal.hilbert(x, N=n)`` cut to the samples' length is the same)."""
    x, m, n = _real_samples(x, axis, n)
    spec = np.fft.fft(x, n=n, axis=axis)
    h = np.zeros(n, dtype=x.dtype)
    h[0] = 1.0
    half = (n + 1) // 2  # positive frequencies are bins 1 .. half-1; an even n has a Nyquist bin at n // 2
    h[1:half] = 2.0
    if n % 2 == 0:
        h[n // 2] = 1.0
    shape = [1] * x.ndim
    shape[axis] = n
    out = np.fft.ifft(spec * h.reshape(shape), axis=axis)
    return out if n == m else np.take(out, np.arange(m), axis=axis)


def hilbert_envelope(x, axis: int = -1, n: int | None = None) -> np.ndarray:
    """Instantaneous amplitude ``|analytic(x, axis, n)|`` along ``axis`` (float32 input stays float32).

    Made as ``sqrt(x^2 + H(x)^2)``, the Hilbert transform ``H`` (the analytic signal's imaginary part) by the real
    FFT: the spectrum turned by -90 degrees (``irfft`` drops the imaginary part this gives the DC and Nyquist
    bins, as the analytic signal leaves them out), half the work of the complex transforms."""
    x, m, n = _real_samples(x, axis, n)
    h = np.fft.irfft(np.fft.rfft(x, n=n, axis=axis) * np.complex64(-1j), n=n, axis=axis)
    if n != m:
        h = np.take(h, np.arange(m), axis=axis)
    return np.sqrt(x * x + h * h)


def running_mean(x, size: int, axis: int = -1) -> np.ndarray:
    """Mean over ``size`` samples centred on each one, the ends extended by their edge values.

    An even ``size`` reaches one sample further back than forward (sample ``i``
    averages ``i - size // 2 .. i + (size - 1) // 2``). The result has ``x``'s float
    type (float64 for integer input); the sums are made in float64.
    """
    x = np.asarray(x)
    size = int(size)
    if size < 1:
        raise ValueError(f"a running mean needs a size of at least 1, not {size}")
    out_dtype = x.dtype if np.issubdtype(x.dtype, np.floating) else np.float64
    if x.shape[axis] == 0:
        return x.astype(out_dtype)
    moved = np.moveaxis(x.astype(np.float64), axis, -1)
    before, after = size // 2, (size - 1) // 2
    padded = np.concatenate([np.repeat(moved[..., :1], before, axis=-1), moved,
                             np.repeat(moved[..., -1:], after, axis=-1)], axis=-1)
    csum = np.concatenate([np.zeros(padded.shape[:-1] + (1,)), np.cumsum(padded, axis=-1)], axis=-1)
    mean = (csum[..., size:] - csum[..., :-size]) / size
    return np.moveaxis(mean, -1, axis).astype(out_dtype)
