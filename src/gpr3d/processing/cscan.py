"""C-scans: horizontal slices of a survey's envelope, gridded on the ground.

For each time window (two-way time after time zero; a depth with ``eps_r``) every
trace gives the mean envelope over that window; traces are averaged into square
cells of ``cell_m``; empty cells within ``fill_m`` of data are filled by a
normalised Gaussian average of their neighbours (lines 0.2-0.5 m apart leave
empty cells between them), the rest stay NaN. The result is georeferenced in the
survey's site frame (``x0``, ``y0``: the centre of cell ``[0, 0]``).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.signal import hilbert

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import CScan
from gpr3d.core.units import velocity_from_eps_r

__all__ = ["CScan", "cscan"]


def cscan(survey, *, cell_m: float, window_s: float, t_start_s=None, eps_r: float | None = None,
          fill_m: float | None = None) -> CScan:
    """C-scans of ``survey`` (needs trace positions): slices ``window_s`` thick starting at ``t_start_s`` (default:
    back to back from time zero to the end of the record)."""
    if survey.positions_xyz is None:
        raise InvalidDataError("a C-scan needs trace positions (a grid survey, a track or poses)")
    if not (np.isfinite(cell_m) and cell_m > 0):
        raise InvalidDataError(f"cell size must be a positive number of metres, got {cell_m!r}")
    record = (survey.n_samples - 1) * survey.dt_s - survey.t0_s
    if not (np.isfinite(window_s) and survey.dt_s <= window_s <= record):
        raise InvalidDataError(f"window must be between one sample ({survey.dt_s * 1e9:g} ns) and the record after "
                               f"time zero ({record * 1e9:g} ns), got {window_s * 1e9:g} ns")
    if eps_r is not None and not (np.isfinite(eps_r) and eps_r >= 1):
        raise InvalidDataError(f"eps_r must be a relative permittivity >= 1, got {eps_r!r}")
    starts = np.arange(0.0, record - window_s + 1e-15, window_s) if t_start_s is None \
        else np.asarray(t_start_s, dtype=float).reshape(-1)
    if starts.size == 0 or np.any(starts < 0) or np.any(starts + window_s > record + 1e-15):
        raise InvalidDataError("slice windows must lie inside the record after time zero")
    fill = 2 * cell_m if fill_m is None else float(fill_m)
    env = np.abs(hilbert(np.asarray(survey.data, dtype=np.float64), axis=1))
    t = np.arange(survey.n_samples) * survey.dt_s - survey.t0_s
    per_trace = np.stack([env[:, (t >= a) & (t < a + window_s)].mean(axis=1) for a in starts])  # (slices, traces)
    xy = survey.positions_xyz[:, :2]
    lo = xy.min(axis=0)
    idx = np.floor((xy - lo) / cell_m + 0.5).astype(np.int64)
    nx, ny = idx.max(axis=0) + 1
    if nx * ny * len(starts) > 100_000_000:
        raise InvalidDataError(f"{len(starts)} slices of {nx} x {ny} cells of {cell_m:g} m: too many; use a larger "
                               "cell or thicker slices")
    flat = idx[:, 0] * ny + idx[:, 1]
    count = np.bincount(flat, minlength=nx * ny).reshape(nx, ny).astype(float)
    sigma = max(fill / cell_m / 2, 0.5)
    near = ndimage.gaussian_filter(count, sigma, mode="constant")
    steps = int(round(fill / cell_m))  # (binary_dilation repeats until nothing changes when told 0 iterations)
    reach = ndimage.binary_dilation(count > 0, iterations=steps) if steps > 0 else count > 0
    out = np.full((len(starts), nx, ny), np.nan, np.float32)
    for k, v in enumerate(per_trace):
        total = np.bincount(flat, weights=v, minlength=nx * ny).reshape(nx, ny)
        cell_mean = total / np.maximum(count, 1)  # (used where count > 0 only)
        with np.errstate(invalid="ignore"):  # cells beyond the kernel: 0 / 0 (never x / 0), left NaN below
            smooth = ndimage.gaussian_filter(total, sigma, mode="constant") / near
        out[k] = np.where(count > 0, cell_mean, np.where(reach, smooth, np.nan))
    depth = None
    if eps_r is not None:
        depth = 0.5 * velocity_from_eps_r(eps_r) * (starts + window_s / 2)
    return CScan(out, float(lo[0]), float(lo[1]), float(cell_m), starts, float(window_s), depth, eps_r)
