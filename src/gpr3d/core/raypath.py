"""Travel time of a ray from an antenna held above the ground to a point below it (refraction at the surface).

An air-launched antenna (a horn on a bridge-deck or road survey, a cart with a gap under the antenna) sits ``h``
above the ground surface. A ray to a point ``d`` below the surface and ``rho`` away horizontally crosses the
surface where Fermat's principle puts it: it spends its horizontal distance mostly in the air, where it is fast,
and bends towards the vertical in the ground (Snell: ``s_air sin(theta_air) = s_ground sin(theta_ground)``). With
``q`` the horizontal distance it runs in the ground, the time

    T(q) = s_air sqrt(h^2 + (rho - q)^2) + s_ground sqrt(d^2 + q^2)

is convex in ``q``; its minimum lies between 0 and ``min(rho, d tan(theta_c))``, ``theta_c`` the critical angle
(``sin(theta_c) = s_air / s_ground``). Newton's method on ``T'(q) = 0`` from the straight ray's crossing, held inside
that range, reaches the minimum to well under a picosecond in four steps (the time error is second order in the
crossing's error, since ``T'`` vanishes there); the tests compare it with a bounded scalar minimisation.

Both the migration kernels (float32) and the forward model (float64) call :func:`air_ground_time`;
:func:`air_ground_times` is the same for numpy arrays (the migration's numpy reference engine).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gpr3d.core.units import C0

__all__ = ["S_AIR", "air_ground_time", "air_ground_times"]

#: slowness of air (s/m)
S_AIR = 1.0 / C0
#: Newton steps (see the module's notes)
STEPS = 4


@njit(fastmath=True, cache=True, inline="always")
def air_ground_time(h, d, rho, s_air, s_ground):
    """One-way time from a point ``h`` above the surface to a point ``d`` below it, ``rho`` apart horizontally.

    ``h <= 0``: no air (the straight ray through the ground, ``s_ground sqrt(rho^2 + (h + d)^2)``);
    ``d <= 0``: the point lies at or above the surface (a straight ray through the air)."""
    if h <= 0.0:
        z = h + d
        return s_ground * math.sqrt(rho * rho + z * z)
    if d <= 0.0:
        z = h + d
        return s_air * math.sqrt(rho * rho + z * z)
    n = s_air / s_ground
    qmax = rho
    if n < 1.0:
        qmax = min(rho, d * n / math.sqrt(1.0 - n * n))
    q = min(rho * d / (h + d), qmax)  # the straight ray's crossing
    for _ in range(STEPS):
        s = rho - q
        a = math.sqrt(h * h + s * s)
        b = math.sqrt(d * d + q * q)
        grad = s_ground * q / b - s_air * s / a
        curv = s_air * (h / a) * (h / a) / a + s_ground * (d / b) * (d / b) / b  # (no cube to underflow)
        q = min(max(q - grad / curv, 0.0 * q), qmax)
    s = rho - q
    return s_air * math.sqrt(h * h + s * s) + s_ground * math.sqrt(d * d + q * q)


def air_ground_times(h, d, rho, s_air, s_ground) -> np.ndarray:
    """:func:`air_ground_time` for arrays (broadcast together), in float64."""
    h, d, rho, s_air, s_ground = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in
                                                       (h, d, rho, s_air, s_ground)))
    z = h + d
    out = np.array(np.where(h <= 0.0, s_ground, s_air) * np.sqrt(rho * rho + z * z))
    live = (h > 0.0) & (d > 0.0)
    if not live.any():
        return out
    h, d, rho, sa, sg = (v[live] for v in (h, d, rho, s_air, s_ground))
    n = sa / sg
    qmax = np.where(n < 1.0, np.minimum(rho, d * n / np.sqrt(np.maximum(1.0 - n * n, 1e-300))), rho)
    q = np.minimum(rho * d / (h + d), qmax)
    for _ in range(STEPS):
        s = rho - q
        a = np.sqrt(h * h + s * s)
        b = np.sqrt(d * d + q * q)
        grad = sg * q / b - sa * s / a
        curv = sa * (h / a) ** 2 / a + sg * (d / b) ** 2 / b
        q = np.clip(q - grad / curv, 0.0, qmax)
    s = rho - q
    out[live] = sa * np.sqrt(h * h + s * s) + sg * np.sqrt(d * d + q * q)
    return out
