"""The traditional grid method, for comparison: 2D migration of each straight line, then pseudo-3D.

Each survey line is migrated on its own, in its vertical plane: Kirchhoff (the
diffraction stack of :class:`~gpr3d.migration.operator.BackProjection` on a
one-column-wide grid) or Stolt's f-k migration (constant velocity, zero offset).
The lines' 2D images are stacked at their positions and the gaps between them
filled by linear interpolation; lines in both directions give two volumes,
which are averaged. That is the "pseudo-3D" volume of grid-line GPR software.
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import velocity_from_eps_r
from gpr3d.core.grid import Grid3D
from gpr3d.migration.operator import BackProjection, antenna_positions

__all__ = ["stolt_migrate", "split_lines", "survey_lines", "kirchhoff_line", "pseudo3d"]


def stolt_migrate(data: np.ndarray, dx_m: float, dt_s: float, eps_r: float, *, pad: int = 2):
    """Stolt f-k migration of a zero-offset B-scan ``(n_traces, n_samples)`` (time zero at sample 0).

    Returns ``(image (n_traces, n_depth), depth_spacing_m)``: the exploding-reflector
    mapping ``omega = (v/2) sign(kz) sqrt(kx^2 + kz^2)`` with its Jacobian, by linear
    interpolation along frequency; the depth spacing is ``(v/2) dt``.
    """
    v2 = 0.5 * velocity_from_eps_r(eps_r)
    nx, nt = data.shape
    NX, NT = pad * nx, pad * nt
    P = np.fft.fft2(np.asarray(data, dtype=np.float64), s=(NX, NT))  # (kx, omega)
    kx = 2 * np.pi * np.fft.fftfreq(NX, dx_m)
    w = 2 * np.pi * np.fft.fftfreq(NT, dt_s)
    kz = w / v2  # output kz grid: same count as omega
    order = np.argsort(w)
    w_sorted = w[order]
    out = np.zeros_like(P)
    for i, k in enumerate(kx):
        wk = np.sign(kz) * v2 * np.sqrt(k * k + kz * kz)
        col = P[i, order]
        re = np.interp(wk, w_sorted, col.real, left=0.0, right=0.0)
        im = np.interp(wk, w_sorted, col.imag, left=0.0, right=0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            jac = np.where(wk != 0, v2 * np.abs(kz) / np.abs(wk), 0.0)
        out[i] = (re + 1j * im) * jac
    img = np.fft.ifft2(out).real[:nx, :nt]
    return img.astype(np.float32), v2 * dt_s


def split_lines(positions_xyz: np.ndarray, *, max_gap_m: float | None = None, max_turn_rad: float = 0.3,
                min_traces: int = 10):
    """Split a trajectory of straight grid lines into lines: lists of trace indices.

    A new line starts after a jump longer than ``max_gap_m`` (default: three times the median step) or a turn
    sharper than ``max_turn_rad`` between consecutive steps; pieces shorter than ``min_traces`` are dropped.
    """
    p = np.asarray(positions_xyz)[:, :2]
    if max_gap_m is None:
        steps = np.hypot(*np.diff(p, axis=0).T)
        moving = steps[steps > 0]
        max_gap_m = 3.0 * float(np.median(moving)) if moving.size else 0.05
    lines, cur = [], [0]
    prev_dir = None
    for i in range(1, len(p)):
        step = p[i] - p[i - 1]
        dist = float(np.hypot(*step))
        new_line = dist > max_gap_m
        if not new_line and dist > 0:
            d = step / dist
            new_line = prev_dir is not None and np.arccos(np.clip(d @ prev_dir, -1, 1)) > max_turn_rad
            prev_dir = d
        if new_line:
            lines.append(cur)
            cur, prev_dir = [], None
        cur.append(i)
    lines.append(cur)
    return [np.asarray(line) for line in lines if len(line) >= min_traces]


def survey_lines(survey) -> list:
    """The trace indices of each straight line of ``survey``: the line files of a grid put together by
    :func:`gpr3d.core.gridsurvey.assemble_grid` (``metadata["grid"]["first_trace"]``), else
    :func:`split_lines` on the positions; lines of fewer than 10 traces are left out."""
    starts = survey.metadata.get("grid", {}).get("first_trace")
    if starts:
        bounds = [*starts, survey.n_traces]
        return [np.arange(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b - a >= 10]
    return split_lines(survey.positions_xyz)


def kirchhoff_line(data, positions_xyz, orientations, offset_m, *, dt_s, t0_s, eps_r, grid: Grid3D, axis: str,
                   coord: float, aperture_deg=50.0, engine="numba", air_gap_m=0.0):
    """Kirchhoff-migrate one line onto its vertical plane: image ``(n_along, nd)`` on ``grid``'s axis
    (``air_gap_m``: the antennas' height above the ground, see :class:`.BackProjection`)."""
    if axis == "x":  # a line along x at y = coord
        g2 = Grid3D(grid.x0, coord, grid.d0, grid.dx, grid.dy, grid.dd, grid.nx, 1, grid.nd)
    else:
        g2 = Grid3D(coord, grid.y0, grid.d0, grid.dx, grid.dy, grid.dd, 1, grid.ny, grid.nd)
    tx, rx = antenna_positions(positions_xyz, orientations, offset_m)
    op = BackProjection(g2, tx, rx, dt_s=dt_s, n_samples=data.shape[1], t0_s=t0_s, eps_r=eps_r,
                        aperture_deg=aperture_deg, obliquity=True, air_gap_m=air_gap_m, engine=engine)
    img = op.adjoint(data)
    return img[:, 0, :] if axis == "x" else img[0, :, :]


def _fill_between(planes: dict, n: int, origin: float, step: float, shape):
    """Linear interpolation of 2D images at sorted coordinates onto ``n`` regular positions (zero outside them);
    a single image fills the positions within half a step of it."""
    coords = np.array(sorted(planes))
    stack = np.stack([planes[c] for c in coords])
    grid_c = origin + step * np.arange(n)
    out = np.zeros((n,) + shape, dtype=np.float32)
    for i, c in enumerate(grid_c):
        if len(coords) == 1:
            if abs(c - coords[0]) <= 0.5 * step * (1 + 1e-9):
                out[i] = stack[0]
            continue
        if c < coords[0] or c > coords[-1]:
            continue
        j = min(int(np.searchsorted(coords, c, side="right")) - 1, len(coords) - 2)
        w = (c - coords[j]) / (coords[j + 1] - coords[j])
        out[i] = (1 - w) * stack[j] + w * stack[j + 1]
    return out


def pseudo3d(survey, grid: Grid3D, *, eps_r: float, method: str = "kirchhoff", aperture_deg=50.0, engine="numba",
             air_gap_m: float = 0.0):
    """Pseudo-3D volume ``(nx, ny, nd)`` from a survey made of straight lines along x and/or y.

    ``survey`` must already be time-zero corrected (``t0_s`` is honoured by
    Kirchhoff; Stolt needs ``t0_s == 0``) and background-removed. ``air_gap_m``: the antennas' height above the
    ground (Kirchhoff only; Stolt refuses one).
    """
    if air_gap_m and method != "kirchhoff":
        raise InvalidDataError(f"an air gap needs method 'kirchhoff' (refraction at the surface), not {method!r}")
    from scipy.signal import hilbert

    lines = survey_lines(survey)
    planes_x, planes_y = {}, {}
    for idx in lines:
        p = survey.positions_xyz[idx]
        d = p[-1, :2] - p[0, :2]
        axis = "x" if abs(d[0]) >= abs(d[1]) else "y"
        coord = float(np.median(p[:, 1] if axis == "x" else p[:, 0]))
        data = survey.data[idx]
        if method == "kirchhoff":
            q = None if survey.orientations_quat_wxyz is None else survey.orientations_quat_wxyz[idx]
            img = kirchhoff_line(data, p, q, survey.offset_m, dt_s=survey.dt_s, t0_s=survey.t0_s, eps_r=eps_r,
                                 grid=grid, axis=axis, coord=coord, aperture_deg=aperture_deg, engine=engine,
                                 air_gap_m=air_gap_m)
        elif method == "stolt":
            along = p[:, 0] if axis == "x" else p[:, 1]
            order = np.argsort(along)
            a, dat = along[order], data[order]
            # the line's mean interval, its length over its intervals (a median is nil where the cart stood still)
            step = float(a[-1] - a[0]) / (len(a) - 1)
            if not step > 0:
                raise InvalidDataError(f"a survey line at {axis} = {coord:g} m has all its traces at one place: "
                                       "Stolt needs a line that moves")
            mig, dz = stolt_migrate(dat, step, survey.dt_s, eps_r)
            # onto the grid: along-line position and depth by linear interpolation
            target_a = grid.x if axis == "x" else grid.y
            z_mig = np.arange(mig.shape[1]) * dz
            tmp = np.stack([np.interp(grid.depth, z_mig, tr) for tr in mig])
            img = np.stack([np.interp(target_a, a, tmp[:, k], left=0, right=0) for k in range(grid.nd)], axis=1)
        else:
            raise InvalidDataError(f"method must be 'kirchhoff' or 'stolt', got {method!r}")
        env = np.abs(hilbert(img, axis=1)).astype(np.float32)
        (planes_x if axis == "x" else planes_y)[coord] = env
    vols = []
    if planes_x:
        v = _fill_between(planes_x, grid.ny, grid.y0, grid.dy, (grid.nx, grid.nd))  # (ny, nx, nd)
        vols.append(np.transpose(v, (1, 0, 2)))
    if planes_y:
        vols.append(_fill_between(planes_y, grid.nx, grid.x0, grid.dx, (grid.ny, grid.nd)))  # (nx, ny, nd)
    if not vols:
        raise InvalidDataError("no straight lines of 10 traces or more found in the survey")
    return np.mean(vols, axis=0).astype(np.float32), {"n_lines_x": len(planes_x), "n_lines_y": len(planes_y)}
