"""One profile migrated in its vertical plane: Kirchhoff, 2D back projection, Stolt or reverse-time migration.

The traces are placed at their distance along the profile (from the file's positions: path length; or a
given trace spacing); the image is ``(n_along, n_depth)`` on a regular grid of ``spacing_m`` along the line and
``depth_spacing_m`` down. Methods:

* ``kirchhoff``: the diffraction stack of :class:`~gpr3d.migration.operator.BackProjection` with the obliquity
  weight and a 50 deg aperture (the tx-rx offset honoured);
* ``backprojection``: the same sum without weights or aperture;
* ``stolt``: f-k migration (constant velocity, zero offset; traces resampled to a constant spacing);
* ``rtm``: 2D Maxwell reverse-time migration (:func:`gpr3d.migration.rtm.rtm_bscan`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.units import C0, velocity_from_eps_r

__all__ = ["ProfileImage", "migrate_profile", "METHODS"]

METHODS = ("kirchhoff", "backprojection", "stolt", "rtm")


@dataclass
class ProfileImage:
    image: np.ndarray  #: (n_along, n_depth) float32
    along_m: np.ndarray  #: positions along the profile (m)
    depth_m: np.ndarray  #: depths (m, positive down)
    method: str
    eps_r: float
    wall_s: float


def _along(survey, trace_spacing_m):
    if trace_spacing_m is not None:
        if not (np.isfinite(trace_spacing_m) and trace_spacing_m > 0):
            raise InvalidDataError(f"trace spacing must be a positive number of metres, got {trace_spacing_m!r}")
        return np.arange(survey.n_traces) * float(trace_spacing_m)
    if survey.positions_xyz is None:
        raise InvalidDataError("the profile has no trace positions: give the trace spacing")
    step = np.hypot(*np.diff(survey.positions_xyz[:, :2], axis=0).T)
    return np.concatenate([[0.0], np.cumsum(step)])


def migrate_profile(survey, *, eps_r: float, method: str = "kirchhoff", max_depth_m: float | None = None,
                    spacing_m: float | None = None, depth_spacing_m: float | None = None,
                    trace_spacing_m: float | None = None, aperture_deg: float = 50.0,
                    air_gap_m: float = 0.0) -> ProfileImage:
    """Migrate the profile ``survey`` (time zero at ``survey.t0_s``) with ``method`` (see the module docstring);
    ``air_gap_m``: the antenna's height above the ground (Kirchhoff and back projection: the rays refract at the
    surface)."""
    if method not in METHODS:
        raise InvalidDataError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if not (np.isfinite(air_gap_m) and air_gap_m >= 0):
        raise InvalidDataError(f"air gap must be a height >= 0 in metres, got {air_gap_m!r}")
    if air_gap_m > 0 and method not in ("kirchhoff", "backprojection"):
        raise InvalidDataError(f"an air gap needs method kirchhoff or backprojection, not {method!r}")
    if not (np.isfinite(eps_r) and eps_r >= 1):
        raise InvalidDataError(f"eps_r must be a relative permittivity >= 1, got {eps_r!r}")
    t_start = time.perf_counter()
    s_along = _along(survey, trace_spacing_m)
    if s_along[-1] <= 0:
        raise InvalidDataError("the profile's traces all lie at one place: nothing to migrate along")
    v = velocity_from_eps_r(eps_r)
    record = survey.n_samples * survey.dt_s - survey.t0_s
    depth = 0.5 * v * (record - 2 * air_gap_m / C0) * 0.95 if max_depth_m is None else float(max_depth_m)
    if not (np.isfinite(depth) and depth > 0):
        raise InvalidDataError(f"max depth must be positive, got {max_depth_m!r}")
    step = float(np.median(np.diff(s_along)[np.diff(s_along) > 0])) if spacing_m is None else float(spacing_m)
    dd = (0.5 * v * survey.dt_s) if depth_spacing_m is None else float(depth_spacing_m)
    if not (step > 0 and dd > 0):
        raise InvalidDataError(f"spacings must be positive, got {step!r} along and {dd!r} in depth")
    n_along = int(np.floor(s_along[-1] / step)) + 1
    nd = int(np.floor(depth / dd)) + 1
    if n_along * nd > 5e7:
        raise InvalidDataError(f"the image of {n_along} x {nd} cells is too large: use larger spacings")
    along = np.arange(n_along) * step
    depths = np.arange(nd) * dd
    if method in ("kirchhoff", "backprojection"):
        from gpr3d.migration.operator import BackProjection, antenna_positions

        pos = np.c_[s_along, np.zeros_like(s_along), np.zeros_like(s_along)]
        tx, rx = antenna_positions(pos, headings_rad=np.zeros(len(pos)), offset_m=survey.offset_m)
        grid = Grid3D(0.0, 0.0, 0.0, step, step, dd, n_along, 1, nd)
        kirch = method == "kirchhoff"
        op = BackProjection(grid, tx, rx, dt_s=survey.dt_s, n_samples=survey.n_samples, t0_s=survey.t0_s,
                            eps_r=eps_r, aperture_deg=aperture_deg if kirch else None, obliquity=kirch,
                            spreading=False, air_gap_m=air_gap_m)
        img = op.adjoint(survey.data)[:, 0, :]
    elif method == "stolt":
        from gpr3d.migration.traditional import stolt_migrate
        from gpr3d.processing.timezero import shift_traces

        # f-k needs time zero at the first sample and a constant trace step: shift by t0, resample along the line
        data = shift_traces(survey.data, survey.t0_s / survey.dt_s) if survey.t0_s > 0 else survey.data
        src = np.clip(np.interp(along, s_along, np.arange(len(s_along))), 0, len(s_along) - 1)
        i0 = np.floor(src).astype(int)
        i1 = np.minimum(i0 + 1, len(s_along) - 1)
        w = (src - i0)[:, None]
        regular = (1 - w) * data[i0] + w * data[i1]
        mig, dz = stolt_migrate(regular, step, survey.dt_s, eps_r)
        z = np.arange(mig.shape[1]) * dz
        img = np.stack([np.interp(depths, z, tr, right=0.0) for tr in mig])
    else:
        from gpr3d.migration.rtm import rtm_bscan

        if survey.frequency_hz is None:
            raise InvalidDataError("reverse-time migration needs the antenna's centre frequency")
        moved = np.r_[True, np.diff(s_along) > 0]  # a stopped wheel repeats a place: its first trace stands for it
        res = rtm_bscan(survey.data[moved], s_along[moved], survey.dt_s, frequency_hz=survey.frequency_hz,
                        depth_m=depth, eps_r=eps_r, t0_s=survey.t0_s)
        down = np.stack([np.interp(depths, res.depth_m, row, right=0.0) for row in res.image])  # (x_rtm, nd)
        img = np.stack([np.interp(along, res.x_m, down[:, k]) for k in range(nd)], axis=1)
    return ProfileImage(np.asarray(img, np.float32), along, depths, method, float(eps_r), time.perf_counter() - t_start)
