"""Physical constants and unit helpers. SI everywhere inside gpr3d."""

from __future__ import annotations

import math

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["C0", "velocity_from_eps_r", "eps_r_from_velocity", "twt_to_depth", "depth_to_twt"]

#: speed of light in vacuum (m/s)
C0 = 299_792_458.0


def velocity_from_eps_r(eps_r: float) -> float:
    """Wave speed (m/s) in a low-loss medium of relative permittivity ``eps_r``."""
    try:
        e = float(eps_r)
    except (TypeError, ValueError):
        raise InvalidDataError(f"eps_r must be a number >= 1, got {eps_r!r}") from None
    if not (e >= 1.0) or not math.isfinite(e):
        raise InvalidDataError(f"eps_r must be a finite number >= 1, got {eps_r!r}")
    return C0 / math.sqrt(e)


def eps_r_from_velocity(velocity_m_s: float) -> float:
    """Relative permittivity from a wave speed (m/s)."""
    if not (0 < velocity_m_s <= C0):
        raise InvalidDataError(f"velocity must be in (0, c], got {velocity_m_s!r} m/s")
    return (C0 / velocity_m_s) ** 2


def twt_to_depth(twt_s, eps_r: float, offset_m: float = 0.0):
    """Depth (m) of a reflector straight below the antenna midpoint from its two-way time (s).

    With a tx-rx offset ``a`` the path is two slanted legs: ``v t / 2 = sqrt(d^2 + (a/2)^2)``.
    """
    v = velocity_from_eps_r(eps_r)
    half_path = v * np.asarray(twt_s, dtype=float) / 2.0
    return np.sqrt(np.maximum(half_path**2 - (offset_m / 2.0) ** 2, 0.0))


def depth_to_twt(depth_m, eps_r: float, offset_m: float = 0.0):
    """Two-way time (s) to a reflector at ``depth_m`` below the antenna midpoint."""
    v = velocity_from_eps_r(eps_r)
    return 2.0 * np.sqrt(np.asarray(depth_m, dtype=float) ** 2 + (offset_m / 2.0) ** 2) / v
