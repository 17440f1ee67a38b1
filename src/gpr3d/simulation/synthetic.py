"""Analytic B-scans of point diffractors: exact travel times for tests and the demo.

Not a physical simulator (that is gprMax, and the forward model of later
stages): each target returns a Ricker wavelet at its exact two-way time
``(|tx - p| + |p - rx|) / v`` with ``1/r`` spreading; the direct wave travels
``offset / c`` through the air. Use it where a test needs known answers.
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.survey import Survey
from gpr3d.core.units import C0, velocity_from_eps_r

__all__ = ["ricker", "point_targets_bscan"]


def ricker(t_s, frequency_hz: float) -> np.ndarray:
    """Ricker wavelet of peak frequency ``frequency_hz``, peaking (value 1) at ``t = 0``."""
    a = (np.pi * frequency_hz * np.asarray(t_s, dtype=float)) ** 2
    return (1.0 - 2.0 * a) * np.exp(-a)


def point_targets_bscan(
    targets_xz,
    *,
    eps_r: float = 6.0,
    frequency_hz: float = 800e6,
    n_traces: int = 121,
    trace_step_m: float = 0.01,
    n_samples: int = 512,
    dt_s: float = 0.05e-9,
    offset_m: float = 0.05,
    t0_s: float = 2e-9,
    direct_wave: float = 2.0,
    noise: float = 0.0,
    seed: int = 0,
) -> Survey:
    """A straight-line B-scan over point diffractors at ``(x, depth)`` metres.

    The antenna midpoint moves along world x from 0 in steps of ``trace_step_m``;
    the wave leaves the surface at ``t0_s`` after the first sample. Ground truth
    goes to ``metadata["truth"]``: per target the apex trace index (fractional)
    and apex time (s, from the first sample).
    """
    v = velocity_from_eps_r(eps_r)
    x = np.arange(n_traces) * trace_step_m
    t = np.arange(n_samples) * dt_s
    data = np.zeros((n_traces, n_samples))
    data += direct_wave * ricker(t[None, :] - t0_s - offset_m / C0, frequency_hz)
    truth = []
    for px, pz in np.atleast_2d(np.asarray(targets_xz, dtype=float)):
        r_tx = np.hypot(x - offset_m / 2 - px, pz)
        r_rx = np.hypot(x + offset_m / 2 - px, pz)
        twt = (r_tx + r_rx) / v
        amp = 1.0 / np.maximum(r_tx + r_rx, 1e-3) * 0.1
        data += amp[:, None] * ricker(t[None, :] - t0_s - twt[:, None], frequency_hz)
        apex_twt = 2 * np.hypot(offset_m / 2, pz) / v
        truth.append({"x_m": float(px), "depth_m": float(pz), "apex_trace": float(px / trace_step_m),
                      "apex_time_s": float(t0_s + apex_twt)})
    if noise:
        data += noise * np.random.default_rng(seed).standard_normal(data.shape)
    pos = np.zeros((n_traces, 3))
    pos[:, 0] = x
    return Survey(
        data=data.astype(np.float32),
        dt_s=dt_s,
        t0_s=0.0,
        positions_xyz=pos,
        offset_m=offset_m,
        frequency_hz=frequency_hz,
        eps_r=eps_r,
        metadata={"format": "synthetic", "generator": "point_targets_bscan", "true_t0_s": t0_s, "truth": truth,
                  "antenna": f"analytic Ricker {frequency_hz / 1e6:g} MHz"},
    )
