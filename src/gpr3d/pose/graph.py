"""Loop closures: a planar pose graph over keyframes of a fused trajectory, solved robustly.

Odometry, even fused with an IMU and smoothed, drifts: its per-frame translation noise integrates into a random
walk in the horizontal position and heading (roll, pitch and height are held by gravity and, on a flat site,
the ground). A cart that crosses ground it has seen before can measure that drift: registering the camera frame
of the revisit to the earlier one (a loop closure) gives their relative pose directly. This module adjusts the
horizontal position and heading of keyframes of the fused trajectory (the drifting directions; roll, pitch and
height are kept) so that the fused frame-to-frame motion between consecutive keyframes and every loop closure
agree, by robust least squares (a Cauchy loss narrowed in steps, graduated: the drift first, then a wrong
closure is down-weighted, not obeyed), and carries the
correction to every IMU sample, interpolated between keyframes.

>>> closed = close_loops(result, closures)                              # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.imu import so3_exp

__all__ = ["LoopClosure", "GraphConfig", "close_loops", "revisits"]


@dataclass
class LoopClosure:
    """The IMU's pose at frame ``j`` in its pose at frame ``i`` (frame indices of a ``FusionResult``), as a loop
    closure measures it, with the standard deviations of its translation (m, each axis) and heading (rad)."""

    i: int
    j: int
    R: np.ndarray
    p: np.ndarray
    sigma_m: float = 0.005
    sigma_rad: float = np.deg2rad(0.2)


@dataclass
class GraphConfig:
    """The fused motion's error per frame (the odometry's: a share of the step plus a floor, and a heading
    error), keyframe spacing and the robust loss's scale (in standard deviations)."""

    trans_frac: float = 0.01
    trans_floor_m: float = 5e-4
    rot_deg: float = 0.03
    keyframe_every: int = 5
    loss_scale: float = 3.0

    def __post_init__(self):
        for name in ("trans_frac", "trans_floor_m", "rot_deg", "loss_scale"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise InvalidDataError(f"{name} must be a positive number, got {getattr(self, name)!r}")
        if not (int(self.keyframe_every) == self.keyframe_every >= 1):
            raise InvalidDataError(f"keyframe_every must be a whole number >= 1, got {self.keyframe_every!r}")


def revisits(t_s, p, R, *, every_s: float = 1.0, radius_m: float = 0.4, max_angle_deg: float = 45.0,
             min_gap_s: float = 15.0) -> list[tuple[int, int]]:
    """Frame pairs ``(i, j)`` (``i`` earlier) of poses ``p`` (n, 3), ``R`` (n, 3, 3) at times ``t_s`` that likely
    see the same ground: frames ``every_s`` apart whose views (0.8 m ahead of the IMU) lie within ``radius_m`` and
    headings within ``max_angle_deg``, at least ``min_gap_s`` apart; for each later frame the nearest earlier."""
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return []
    for name, v in (("every_s", every_s), ("radius_m", radius_m), ("max_angle_deg", max_angle_deg)):
        if not (np.isfinite(v) and v > 0):
            raise InvalidDataError(f"{name} must be a positive number, got {v!r}")
    step = max(1, int(round(every_s / np.median(np.diff(t)))))
    idx = np.arange(0, t.size, step)
    Rk = np.asarray(R)[idx]
    look = np.asarray(p)[idx, :2] + 0.8 * Rk[:, :2, 0]
    yaw = _yaw(Rk)
    out = []
    for b in range(idx.size):
        early = np.nonzero(t[idx] < t[idx[b]] - min_gap_s)[0]
        if early.size == 0:
            continue
        dist = np.linalg.norm(look[early] - look[b], axis=1)
        dang = np.abs(_wrap(yaw[early] - yaw[b]))
        ok = (dist < radius_m) & (dang < np.deg2rad(max_angle_deg))
        if ok.any():
            out.append((int(idx[early[ok][np.argmin(dist[ok])]]), int(idx[b])))
    return out


def _yaw(R) -> np.ndarray:
    R = np.asarray(R)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def close_loops(res, closures: list, cfg: GraphConfig | None = None, *, report: dict | None = None):
    """The fusion result with its horizontal positions and headings adjusted to the loop ``closures``.

    Returns a new :class:`~gpr3d.pose.eskf.FusionResult` (poses at every IMU sample and at the frames) and
    leaves ``res`` as it was. Closures whose frames are not keyframes are moved to the nearest keyframe with
    the fused motion between. A closure that disagrees with the fused motion by more than the odometry's drift
    between its frames can explain (99.9 %) is left out before the solve, one that the solution leaves more than 5
    sigmas off is left out of a final solve; ``report`` (a dict) receives the counts."""
    cfg = cfg or GraphConfig()
    m = res.frame_p.shape[0]
    if m < 2:
        raise InvalidDataError("loop closing needs a fused trajectory with at least two frames")
    if not closures:
        return res
    kf = np.arange(0, m, int(cfg.keyframe_every))
    if kf[-1] != m - 1:
        kf = np.append(kf, m - 1)
    n = kf.size
    P0 = res.frame_p[kf, :2]
    Y0 = _yaw(res.frame_R[kf])
    # odometry edges between consecutive keyframes, in the first one's heading frame
    steps = np.linalg.norm(np.diff(res.frame_p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(steps)])
    edges = []
    for a in range(n - 1):
        i, j = kf[a], kf[a + 1]
        c, s = np.cos(Y0[a]), np.sin(Y0[a])
        d = np.array([[c, s], [-s, c]]) @ (P0[a + 1] - P0[a])
        k = j - i
        st = np.sqrt(k * cfg.trans_floor_m**2 + (cfg.trans_frac * (cum[j] - cum[i])) ** 2 / k)
        edges.append((a, a + 1, d, _wrap(Y0[a + 1] - Y0[a]), st, np.sqrt(k) * np.deg2rad(cfg.rot_deg)))
    # loop edges: moved to the nearest keyframes through the fused motion
    gated = 0
    for lc in closures:
        if not (0 <= lc.i < m and 0 <= lc.j < m) or lc.i == lc.j:
            raise InvalidDataError(f"loop closure ({lc.i}, {lc.j}) names frames outside 0..{m - 1} or one frame twice")
        a, b = int(np.argmin(np.abs(kf - lc.i))), int(np.argmin(np.abs(kf - lc.j)))
        if a == b:
            continue
        Ti, Tj = np.eye(4), np.eye(4)
        Ti[:3, :3], Ti[:3, 3] = res.frame_R[lc.i], res.frame_p[lc.i]
        Tj[:3, :3], Tj[:3, 3] = res.frame_R[lc.j], res.frame_p[lc.j]
        Ta, Tb = np.eye(4), np.eye(4)
        Ta[:3, :3], Ta[:3, 3] = res.frame_R[kf[a]], res.frame_p[kf[a]]
        Tb[:3, :3], Tb[:3, 3] = res.frame_R[kf[b]], res.frame_p[kf[b]]
        Tij = np.eye(4)
        Tij[:3, :3], Tij[:3, 3] = lc.R, lc.p
        # keyframe b in keyframe a: fused (a -> i), measured (i -> j), fused (j -> b)
        Tab = np.linalg.inv(Ta) @ Ti @ Tij @ np.linalg.inv(Tj) @ Tb
        # into the planar heading frame of a: rotate the motion by a's roll and pitch
        Ra = res.frame_R[kf[a]]
        Rz = so3_exp([0.0, 0.0, Y0[a]])
        d = (Rz.T @ Ra @ Tab[:3, 3])[:2]
        dyaw = _wrap(_yaw(Ra @ Tab[:3, :3]) - Y0[a])
        extra = abs(lc.i - kf[a]) + abs(lc.j - kf[b])
        st = np.hypot(lc.sigma_m, np.sqrt(extra) * cfg.trans_floor_m * 3)
        # the drift the odometry can have gathered between a and b: its per-frame noise and its heading's
        nf = abs(kf[b] - kf[a])
        fr = np.arange(min(kf[a], kf[b]), max(kf[a], kf[b]))
        drift_t2 = nf * cfg.trans_floor_m**2 + np.sum((cfg.trans_frac * steps[fr]) ** 2)
        drift_r2 = nf * np.deg2rad(cfg.rot_deg) ** 2
        fused_d = (Rz.T @ (res.frame_p[kf[b]] - res.frame_p[kf[a]]))[:2]
        fused_y = _wrap(Y0[b] - Y0[a])
        var_t = drift_t2 + drift_r2 * float(fused_d @ fused_d) + st**2
        if (float(np.sum((d - fused_d) ** 2)) / var_t > 13.8
                or _wrap(dyaw - fused_y) ** 2 / (drift_r2 + lc.sigma_rad**2) > 10.8):
            gated += 1
            continue
        edges.append((a, b, d, dyaw, st, np.hypot(lc.sigma_rad, np.sqrt(extra) * np.deg2rad(cfg.rot_deg))))
    ne = len(edges)
    ia = np.array([e[0] for e in edges])
    ib = np.array([e[1] for e in edges])
    D = np.array([e[2] for e in edges])
    DY = np.array([e[3] for e in edges])
    ST = np.array([e[4] for e in edges])
    SR = np.array([e[5] for e in edges])

    def unpack(x):  # keyframe 0 is held where the fusion put it (the site's start)
        xy = np.vstack([P0[:1], x[: 2 * (n - 1)].reshape(n - 1, 2)])
        yaw = np.concatenate([Y0[:1], x[2 * (n - 1):]])
        return xy, yaw

    def residuals(x):
        xy, yaw = unpack(x)
        c, s = np.cos(yaw[ia]), np.sin(yaw[ia])
        dx, dy = xy[ib, 0] - xy[ia, 0], xy[ib, 1] - xy[ia, 1]
        ex = (c * dx + s * dy - D[:, 0]) / ST
        ey = (-s * dx + c * dy - D[:, 1]) / ST
        ez = _wrap(yaw[ib] - yaw[ia] - DY) / SR
        return np.concatenate([ex, ey, ez])

    sp = lil_matrix((3 * ne, 3 * (n - 1)), dtype=np.int8)
    for r, (a, b) in enumerate(zip(ia, ib)):
        for node in (a, b):
            if node == 0:
                continue
            cols = [2 * (node - 1), 2 * (node - 1) + 1, 2 * (n - 1) + node - 1]
            for row in (r, ne + r, 2 * ne + r):
                sp[row, cols] = 1
    x = np.concatenate([P0[1:].reshape(-1), Y0[1:]])
    # graduated: the drift makes every true closure look like an outlier at first (tens of sigmas), so the
    # loss starts wide and narrows to its scale, each solve starting from the last
    spc = sp.tocsr()
    for scale in cfg.loss_scale * np.array([1000.0, 100.0, 10.0, 1.0]):
        x = least_squares(residuals, x, jac_sparsity=spc, loss="cauchy", f_scale=scale, method="trf",
                          x_scale="jac", max_nfev=100).x
    # closures the solution leaves past 5 sigmas are wrong: solve once more without them
    r = residuals(x).reshape(3, ne)
    loop = np.arange(ne) >= n - 1
    bad = loop & (np.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2) > 5.0)
    if bad.any():
        keep = ~bad
        ia, ib, D, DY, ST, SR = ia[keep], ib[keep], D[keep], DY[keep], ST[keep], SR[keep]
        rows = np.concatenate([np.nonzero(keep)[0] + k * ne for k in range(3)])
        ne = int(keep.sum())
        spc = spc[rows]
        x = least_squares(residuals, x, jac_sparsity=spc, loss="cauchy", f_scale=cfg.loss_scale, method="trf",
                          x_scale="jac", max_nfev=100).x
    if report is not None:
        report.update(closures=len(closures), gated=gated, rejected=int(bad.sum()), used=int(ne - (n - 1)))
    xy, yaw = unpack(x)
    dpos = np.zeros((n, 3))
    dpos[:, :2] = xy - P0
    dyaw = _wrap(yaw - Y0)
    # every pose takes its keyframes' correction, interpolated: a turn about z through its own position
    # (keyframe positions move by dpos; the frames between move along)

    def correct(t_query, p, R, v):
        w = np.interp(t_query, res.frame_t_s[kf], np.arange(n))
        a = np.clip(np.floor(w).astype(int), 0, n - 1)
        b = np.clip(a + 1, 0, n - 1)
        f = (w - a)[:, None]
        # the correction of a pose between keyframes: each keyframe's rigid planar motion applied to it
        def apply(k):
            Rz = np.stack([so3_exp([0.0, 0.0, dy]) for dy in dyaw[k]])
            pk = res.frame_p[kf[k]]
            return np.einsum("nij,nj->ni", Rz, p - pk) + pk + dpos[k], Rz
        pa, Ra_ = apply(a)
        pb, Rb_ = apply(b)
        yawc = dyaw[a] + f[:, 0] * _wrap(dyaw[b] - dyaw[a])
        Rz = np.stack([so3_exp([0.0, 0.0, dy]) for dy in yawc])
        return (1 - f) * pa + f * pb, Rz @ R, np.einsum("nij,nj->ni", Rz, v)

    p_new, R_new, v_new = correct(res.t_s, res.p, res.R, res.v)
    fp, fR, _ = correct(res.frame_t_s, res.frame_p, res.frame_R, np.zeros_like(res.frame_p))
    return replace(res, p=p_new, R=R_new, v=v_new, frame_p=fp, frame_R=fR)
