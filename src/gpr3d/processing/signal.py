"""Where a record's signal ends: the time after which neighbouring traces no longer look alike.

A reflection or a diffraction reaches neighbouring traces at nearly the same time, so two traces a few
centimetres apart carry nearly the same wiggle; receiver noise does not (each trace draws its own). The
*coherence* of a time window is the correlation of every trace with the next one over that window, all traces
pooled::

    r_k = sum_j sum_{t in k} x_j(t) x_{j+1}(t) / sum_j sum_{t in k} (x_j(t)^2 + x_{j+1}(t)^2) / 2

(-1 .. 1; about 0 for noise alone, with a spread of 1 / sqrt(traces x samples) about it), pooled over runs of
``BLOCK_TRACES`` neighbouring traces so that a target that only a few traces see is not diluted by the others. It
does not care for
gain: a time-varying gain multiplies numerator and denominator alike, so the ramps that radars apply while
recording (which make the late noise as loud as the early signal) do not hide where the signal ends.

The signal ends after the last window where some run's coherence (averaged with its two neighbouring windows)
stands above ``max(MIN_COHERENCE, NOISE_SIGMAS / sqrt(pairs x samples))``, plus ``MARGIN_WINDOWS`` windows. A record that is
coherent to its end, or nowhere, is not cut (``end_s`` None). :func:`gpr3d.migration.reconstruct.reconstruct`
ends its grid there: a voxel deeper than half the two-way time of the signal's end at the ground's speed
receives only later samples, which hold nothing but noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["SignalEnd", "signal_end", "window_coherence", "BLOCK_TRACES", "MARGIN_WINDOWS", "MIN_COHERENCE",
           "MIN_TRACES", "NOISE_SIGMAS"]

#: the coherence a window must exceed to count as signal (at the least: more where few traces are pooled)
MIN_COHERENCE = 0.1
#: ... and how many of pure noise's standard deviations (1 / sqrt(pairs x samples) in a run) it must stand above
NOISE_SIGMAS = 6.0
#: windows kept after the last coherent one (the wavelet's tail and the window's own width)
MARGIN_WINDOWS = 2
#: fewer traces than this: the coherence is not told apart from noise, and the record is not cut
MIN_TRACES = 24
#: a window spans this many periods of the frequency given
WINDOW_PERIODS = 2.0
#: the coherence is pooled over runs of this many neighbouring trace pairs, and a window counts as signal where
#: any run's does: a target seen by a few traces stays as visible as in a short record, not diluted by the rest
BLOCK_TRACES = 48


@dataclass
class SignalEnd:
    """What :func:`signal_end` found."""

    #: seconds after the first sample at which the signal ends; None: it reaches the record's end, or nothing in
    #: the record stands above the noise, or there are too few traces to tell (``reason`` says which)
    end_s: float | None
    window_samples: int  #: the windows' length (samples)
    threshold: float  #: the coherence a window had to exceed
    reason: str  #: one line for people
    #: each run of traces' coherence in each window (runs, windows), before the three-window average
    coherence: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        return {"end_s": self.end_s, "window_samples": self.window_samples, "threshold": self.threshold,
                "reason": self.reason}


def window_coherence(data: np.ndarray, w: int, block: int | None = None) -> np.ndarray:
    """The coherence between neighbouring traces of ``data`` (n_traces, n_samples) in each window of ``w``
    samples (the last, shorter one included): see the module's text. ``block``: pooled over runs of that many
    trace pairs (the last run takes the remainder of a short one), an array (runs, windows); None: over all
    traces, an array (windows,). A window with no energy has coherence 0."""
    x = np.asarray(data, dtype=np.float32)
    n = x.shape[1]
    k = -(-n // w)
    pad = k * w - n
    if pad:
        x = np.pad(x, ((0, 0), (0, pad)))
    a, b = x[:-1], x[1:]
    cross = (a * b).reshape(a.shape[0], k, w).sum(axis=2, dtype=np.float64)
    power = (a * a + b * b).reshape(a.shape[0], k, w).sum(axis=2, dtype=np.float64) / 2
    if block is None:
        cross, power = cross.sum(axis=0), power.sum(axis=0)
    else:
        starts = np.arange(0, max(a.shape[0] - block + 1, 1), block)
        cross, power = np.add.reduceat(cross, starts), np.add.reduceat(power, starts)
    return cross / np.maximum(power, np.finfo(np.float64).tiny)  # (no energy: no cross term either, 0)


def signal_end(data: np.ndarray, dt_s: float, frequency_hz: float) -> SignalEnd:
    """Where the signal of ``data`` (n_traces, n_samples; neighbouring traces next to each other on the ground)
    ends: the time after which each window's coherence stays at noise's (see the module's text).

    Parameters
    ----------
    data : ndarray
        The traces, their background removed (a flat layer repeated in every trace is coherent to the end of
        the ringing; removing it first leaves the targets' own signal).
    dt_s : float
        The sample interval (s).
    frequency_hz : float
        The traces' frequency: a window spans ``WINDOW_PERIODS`` periods of it.
    """
    data = np.asarray(data)
    if data.ndim != 2:
        raise ValueError(f"data must be (n_traces, n_samples), got shape {data.shape}")
    if not (dt_s > 0 and math.isfinite(dt_s)) or not (frequency_hz > 0 and math.isfinite(frequency_hz)):
        raise ValueError(f"dt_s and frequency_hz must be positive, got {dt_s!r} and {frequency_hz!r}")
    n_traces, n = data.shape
    w = max(4, int(round(WINDOW_PERIODS / (frequency_hz * dt_s))))
    if n_traces < MIN_TRACES or n < 3 * w:
        return SignalEnd(None, w, math.nan, f"{n_traces} traces of {n} samples are too few to tell signal from "
                         "noise", np.zeros(0))
    r = window_coherence(data, w, BLOCK_TRACES)  # (runs of traces, windows)
    pairs = (n_traces - 1) if r.shape[0] == 1 else BLOCK_TRACES
    threshold = max(MIN_COHERENCE, NOISE_SIGMAS / math.sqrt(pairs * w))
    kernel = np.ones(3)
    smooth = (np.apply_along_axis(np.convolve, 1, r, kernel, mode="same")
              / np.convolve(np.ones(r.shape[1]), kernel, mode="same"))
    above = np.flatnonzero((smooth > threshold).any(axis=0))
    if above.size == 0:
        return SignalEnd(None, w, threshold, "no window of the record stands above the noise", r)
    end = (int(above[-1]) + 1 + MARGIN_WINDOWS) * w
    if end >= n:
        return SignalEnd(None, w, threshold, "the signal reaches the record's end", r)
    return SignalEnd(end * dt_s, w, threshold, f"no signal above the noise after {end * dt_s * 1e9:.1f} ns "
                     f"(coherence of neighbouring traces <= {threshold:.2f})", r)
