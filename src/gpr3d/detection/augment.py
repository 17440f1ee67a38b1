"""Training-time changes of a record that keep its labels true: the detector sees more kinds of B-scan.

Real recordings differ from one another (and from our synthetic ones) in ways that do not
move a target: the cart's speed and the trace interval (how wide a hyperbola looks in
traces), the display gain (how bright and how clipped), and the noise floor. Each of these
is drawn once per training window (:func:`augment_record`), on the processed record the
detector sees (:func:`gpr3d.detection.windows.prepare`), and the labels follow:

- **stretch**: the trace axis is resampled by a factor ``s`` (trace ``i`` lands at ``i s``),
  so boxes and apexes move and widen with it; the time axis is untouched (a row keeps its time);
- **gain**: the record's normalising amplitude is divided by ``g`` (``g > 1``: brighter, more
  of the strong echoes clipped; ``g < 1``: dimmer);
- **noise**: white Gaussian noise of a drawn share of the record's amplitude.

Polarity is never flipped: it tells metal from air and plastic.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["Augment", "stretch_traces", "stretch_labels", "augment_record"]


@dataclass(frozen=True)
class Augment:
    """How far the training windows are changed (each draw uniform in the logarithm of its range).

    Attributes
    ----------
    stretch : tuple of float
        Range of the trace-axis factor, ``0.25 <= low <= high <= 4``; ``(1, 1)``: none.
    gain : tuple of float
        Range of the contrast factor, ``0.1 <= low <= high <= 10``; ``(1, 1)``: none.
    noise : float
        Largest noise standard deviation, as a share of the record's normalising amplitude, 0..1.

    Raises
    ------
    InvalidDataError
        A range out of order or out of its bounds, in one line naming it.
    """

    stretch: tuple = (0.7, 1.4)
    gain: tuple = (0.6, 1.8)
    noise: float = 0.15

    def __post_init__(self):
        for name, lo_b, hi_b in (("stretch", 0.25, 4.0), ("gain", 0.1, 10.0)):
            v = getattr(self, name)
            try:
                lo, hi = (float(x) for x in v)
            except (TypeError, ValueError):
                raise InvalidDataError(f"augment {name} must be two numbers (low, high), got {v!r}") from None
            if not (lo_b <= lo <= hi <= hi_b):
                raise InvalidDataError(f"augment {name} must satisfy {lo_b} <= low <= high <= {hi_b}, got {v!r}")
            object.__setattr__(self, name, (lo, hi))
        if not (isinstance(self.noise, (int, float)) and 0.0 <= float(self.noise) <= 1.0):
            raise InvalidDataError(f"augment noise must lie in 0..1, got {self.noise!r}")

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def stretch_traces(processed: np.ndarray, factor: float) -> np.ndarray:
    """The record ``(n, rows)`` resampled along its traces: old trace ``i`` at new column ``i * factor``.

    Linear interpolation between neighbouring traces; the result has ``round((n - 1) factor) + 1``
    traces (at least 2).
    """
    proc = np.asarray(processed, dtype=np.float32)
    n = proc.shape[0]
    m = max(2, int(round((n - 1) * factor)) + 1)
    src = np.minimum(np.arange(m) / factor, n - 1.0)  # the last column may fall past the record: its last trace
    i0 = np.floor(src).astype(np.int64)
    i1 = np.minimum(i0 + 1, n - 1)
    w = (src - i0).astype(np.float32)[:, None]
    return (proc[i0] * (1.0 - w) + proc[i1] * w).astype(np.float32)


def stretch_labels(labels: dict, factor: float) -> dict:
    """A copy of ``labels`` whose boxes and apexes follow :func:`stretch_traces` (trace ``x`` -> ``x * factor``)."""
    out = []
    for lab in labels["labels"]:
        new = dict(lab)
        x0, t0, x1, t1 = (float(v) for v in lab["box"])
        new["box"] = [x0 * factor, t0, x1 * factor, t1]
        new["apex_trace"] = float(lab["apex_trace"]) * factor
        out.append(new)
    return {**labels, "labels": out}


def _log_uniform(rng, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) if hi > lo else lo


def augment_record(processed: np.ndarray, labels: dict, scale: float, rng: np.random.Generator,
                   aug: Augment) -> tuple[np.ndarray, dict, float]:
    """One draw of ``aug`` on a processed record: ``(processed, labels, scale)`` changed together.

    ``scale`` is the record's normalising amplitude (:func:`gpr3d.detection.windows.record_scale`
    of the unchanged record); the noise is drawn relative to it and the returned scale is it
    divided by the drawn gain. Draws, in order: stretch, gain, noise share, then the noise.
    """
    s = _log_uniform(rng, *aug.stretch)
    g = _log_uniform(rng, *aug.gain)
    share = float(rng.uniform(0.0, aug.noise)) if aug.noise > 0 else 0.0
    proc = np.asarray(processed, dtype=np.float32)
    if s != 1.0:
        proc = stretch_traces(proc, s)
        labels = stretch_labels(labels, s)
    if share > 0:
        proc = (proc + rng.normal(0.0, share * scale, size=proc.shape)).astype(np.float32)
    return proc, labels, scale / g
