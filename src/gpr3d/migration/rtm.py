"""2D reverse-time migration (RTM) of a B-scan with Maxwell's equations, TM mode (E_y, H_x, H_z).

The recorded traces are injected, time-reversed, at their antenna positions on the surface of a 2D model of the
host, and the field is run backwards in time with the FDTD (Yee) scheme until time zero. The imaging condition
is the exploding reflector's: every reflector is taken to fire at time zero, so a zero-offset section is the
field that such sources would send up at half the wave speed; run back to time zero in a model whose speed is
halved (eps_r x 4), the field focuses on the reflectors, and the image is the field at time zero. Absorbing
sponge layers (Cerjan damping) surround the model on all four sides, so nothing returns from its edges.

Velocity: constant ``eps_r`` or ``layers = [(top_depth_m, eps_r), ...]`` (as :func:`.operator.effective_slowness`);
the field is computed in the layered model, so the focusing follows the refraction at each interface, which the
straight rays of Kirchhoff migration and the constant velocity of Stolt's do not.

Assumptions: zero offset (the tx-rx offset is small next to the depth), a flat surface, no loss (the back
propagation does not amplify, so deep reflectors come out weak).

The FDTD step runs in numba, parallel over columns (a model of fewer than :data:`SERIAL_CELLS` cells on one
thread); a B-scan of a few hundred traces takes well under a second to a few seconds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0

__all__ = ["RTMResult", "rtm_bscan", "eps_column", "SERIAL_CELLS"]

#: the largest model (cells x time steps) rtm_bscan will run: beyond it, a one-line error asks for coarser cells
MAX_WORK = 2e11
#: models of fewer cells than this (sponges included) run the FDTD steps on one thread: each step is two parallel
#: regions, and where a step's work is this small a region's barrier can cost more than the work whenever another
#: process holds the other core (the first demo's B-scan beside the background compilation of the kernels: 561
#: steps of 204,000 cells took 3.4-7.1 s on two threads, 0.03 s on one; alone, 0.05 s against 0.08 s:
#: benchmarks/results/bench_stages.md)
SERIAL_CELLS = 250_000


@dataclass
class RTMResult:
    """The migrated section: ``image (nx, nz)`` float32 on ``x_m`` (along the line) x ``depth_m`` (from 0 at the
    surface, positive down), with the cell size, the number of time steps, the wall time and the threads the FDTD
    steps ran on."""

    image: np.ndarray
    x_m: np.ndarray
    depth_m: np.ndarray
    cell_m: float
    steps: int
    wall_s: float
    threads: int = 1


def eps_column(depth_m: np.ndarray, eps_r=None, layers=None) -> np.ndarray:
    """eps_r at each depth: constant, or from ``layers = [(top_depth_m, eps_r), ...]`` (first top 0, increasing)."""
    depth_m = np.asarray(depth_m, float)
    if layers is None:
        if eps_r is None:
            raise InvalidDataError("give eps_r or layers for the migration velocity")
        return np.full(depth_m.shape, float(eps_r))
    tops = np.array([lay[0] for lay in layers], float)
    eps = np.array([lay[1] for lay in layers], float)
    if tops.size == 0 or tops[0] != 0 or np.any(np.diff(tops) <= 0):
        raise InvalidDataError("layers must start at depth 0 and deepen")
    if not np.all(np.isfinite(eps)) or np.any(eps < 1):
        raise InvalidDataError(f"layer eps_r must be finite and >= 1, got {eps.tolist()}")
    return eps[np.searchsorted(tops, depth_m, side="right") - 1]


def _sponge(n_core: int, pad: int) -> np.ndarray:
    # Cerjan damping per step: 1 inside, exp(-(a d)^2) at d cells into the pad (about 0.92 at the outer edge)
    g = np.ones(n_core + 2 * pad)
    a = 0.29 / pad
    d = np.arange(pad, 0, -1)
    g[:pad] = np.exp(-(a * d) ** 2)
    g[pad + n_core:] = g[:pad][::-1]
    return g


@njit(parallel=True, fastmath=True, cache=True)
def _run(ey, hx, hz, ce, ch, gx, gz, src, src_i0, ks):
    """``src.shape[0]`` FDTD steps; at step n, ``src[n]`` is added to E_y on the surface row ``ks`` from column
    ``src_i0``. ``ce``: c dt / (eps h) per cell; ``ch``: c dt / h; ``gx``, ``gz``: the sponges' damping."""
    nx, nz = ey.shape
    ns, nsrc = src.shape
    for n in range(ns):
        for i in prange(nx):
            for k in range(nz - 1):
                hx[i, k] = (hx[i, k] + ch * (ey[i, k + 1] - ey[i, k])) * gx[i] * gz[k]
            if i < nx - 1:
                for k in range(nz):
                    hz[i, k] = (hz[i, k] - ch * (ey[i + 1, k] - ey[i, k])) * gx[i] * gz[k]
        for i in prange(1, nx - 1):
            for k in range(1, nz - 1):
                curl = (hx[i, k] - hx[i, k - 1]) - (hz[i, k] - hz[i - 1, k])
                ey[i, k] = (ey[i, k] + ce[i, k] * curl) * gx[i] * gz[k]
        for j in range(nsrc):
            ey[src_i0 + j, ks] += src[n, j]


def rtm_bscan(data, x_m, dt_s: float, *, frequency_hz: float, depth_m: float, eps_r=None, layers=None,
              t0_s: float = 0.0, cell_m: float | None = None, pad_cells: int = 40) -> RTMResult:
    """Reverse-time migrate the B-scan ``data (n_traces, n_samples)`` recorded at ``x_m`` along the line.

    ``dt_s``: sample interval; ``t0_s``: time zero (s after the first sample); ``frequency_hz``: the antenna's
    centre frequency (sets the cell: a tenth of the shortest wavelength, at twice it, in the slowest layer, unless
    ``cell_m`` is given); ``depth_m``: the deepest depth imaged. ``pad_cells``: thickness of the absorbing sponges.
    """
    t_start = time.perf_counter()
    data = np.asarray(data, dtype=np.float64)
    x = np.asarray(x_m, dtype=float).reshape(-1)
    if data.ndim != 2 or data.shape[0] < 2 or data.shape[1] < 2:
        raise InvalidDataError(f"data must be a B-scan (n_traces >= 2, n_samples >= 2), got shape {data.shape}")
    if x.size != data.shape[0]:
        raise InvalidDataError(f"x_m has {x.size} positions but the data have {data.shape[0]} traces")
    if not np.all(np.isfinite(data)):
        raise InvalidDataError("the data hold NaN or infinite samples")
    if not np.all(np.isfinite(x)) or np.any(np.diff(x) <= 0):
        raise InvalidDataError("x_m must increase strictly along the line (a straight B-scan, traces in order)")
    for name, val in (("dt_s", dt_s), ("frequency_hz", frequency_hz), ("depth_m", depth_m)):
        if not (isinstance(val, (int, float, np.floating)) and math.isfinite(val) and val > 0):
            raise InvalidDataError(f"{name} must be a positive number, got {val!r}")
    if cell_m is not None and not (math.isfinite(cell_m) and cell_m > 0):
        raise InvalidDataError(f"cell_m must be a positive number of metres, got {cell_m!r}")
    if not isinstance(pad_cells, (int, np.integer)) or pad_cells < 10:
        raise InvalidDataError(f"pad_cells must be a whole number >= 10, got {pad_cells!r}")
    eps_probe = eps_column(np.array([0.0, depth_m]), eps_r, layers)  # checks the velocity model
    eps_all = eps_probe if layers is None else np.array([lay[1] for lay in layers], float)
    if not np.all(eps_all >= 1):
        raise InvalidDataError(f"eps_r must be >= 1, got {eps_all.tolist()}")
    # the exploding reflector: the field travels at half the speed, i.e. in eps_r x 4
    eps_slow, eps_fast = 4.0 * float(eps_all.max()), 4.0 * float(eps_all.min())
    h = cell_m or C0 / (2.0 * frequency_hz * math.sqrt(eps_slow)) / 10.0
    nxc = int(math.floor((x[-1] - x[0]) / h)) + 1
    nzc = int(math.floor(depth_m / h)) + 1
    p = int(pad_cells)
    nx, nz = nxc + 2 * p, nzc + 2 * p + 1  # the top pad lies above the surface row (row p)
    dt = 0.95 * h / (C0 / math.sqrt(eps_fast) * math.sqrt(2.0))
    t_end = (data.shape[1] - 1) * dt_s - t0_s  # the last sample's time after time zero
    if not t_end > 0:
        raise InvalidDataError(f"time zero ({t0_s!r} s) must lie inside the record ({data.shape[1]} samples of "
                               f"{dt_s!r} s)")
    steps = max(1, int(math.ceil(t_end / dt)))
    if float(nx) * nz * steps > MAX_WORK:
        raise InvalidDataError(f"the RTM model would be {nx} x {nz} cells x {steps} steps (cell {h * 1e3:.2f} mm): "
                               "give a coarser cell_m or a shallower depth_m")
    ks = p
    depth_rows = (np.arange(nz) - ks) * h
    eps = 4.0 * eps_column(np.maximum(depth_rows, 0.0), eps_r, layers)
    eps[:ks] = eps[ks]  # above the surface: the top layer (the sponge absorbs there; no air-ground reflection)
    ce = np.ascontiguousarray(np.broadcast_to((C0 * dt / h) / eps, (nx, nz)), dtype=np.float32)
    # the traces resampled onto the surface cells (linear along x) and in time onto the FDTD steps, reversed
    xs = x[0] + h * np.arange(nxc)
    t_steps = t_end - dt * np.arange(steps)  # the field runs backwards from the last sample to time zero
    u = (t_steps + t0_s) / dt_s  # fractional sample index of each step
    i0 = np.clip(np.floor(u).astype(int), 0, data.shape[1] - 2)
    fr = np.clip(u - i0, 0.0, 1.0)
    in_time = data[:, i0] * (1 - fr) + data[:, i0 + 1] * fr  # (n_traces, steps)
    j = np.clip(np.searchsorted(x, xs, side="right") - 1, 0, x.size - 2)
    fx = np.clip((xs - x[j]) / (x[j + 1] - x[j]), 0.0, 1.0)
    src = (in_time[j].T * (1 - fx) + in_time[j + 1].T * fx).astype(np.float32)  # (steps, nxc)
    ey = np.zeros((nx, nz), np.float32)
    hx = np.zeros((nx, nz), np.float32)
    hz = np.zeros((nx, nz), np.float32)
    had = numba.get_num_threads()
    threads = 1 if nx * nz < SERIAL_CELLS else had
    numba.set_num_threads(threads)
    try:
        _run(ey, hx, hz, ce, np.float32(C0 * dt / h), _sponge(nxc, p).astype(np.float32),
             _sponge(nzc + 1, p)[: nz].astype(np.float32), src, p, ks)
    finally:
        numba.set_num_threads(had)
    image = np.ascontiguousarray(ey[p: p + nxc, ks: ks + nzc])
    return RTMResult(image=image, x_m=xs, depth_m=h * np.arange(nzc), cell_m=h, steps=steps,
                     wall_s=time.perf_counter() - t_start, threads=threads)
