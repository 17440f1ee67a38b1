"""Targets from a 3D image: a ridge map, groups, a weighted Hough transform, robust line fits.

Migrated energy focuses on the surface that reflected it, so each image column's
envelope maximum marks the top of whatever lies below that point. Extraction
works on that ridge map (value and depth of the maximum per column):

1. keep the columns above ``threshold`` x a robust reference level of the map; gather them in
   groups: connected parts after closing gaps narrower than ``group_gap_m`` (a rebar imaged as a row of
   bright crossings and faint stretches between them is one group);
2. in each group, find straight lines one after the other: the peak of a Hough transform weighted by
   ridge value (the line through the most energy, whatever its pieces), refined by a weighted principal
   axis; its inlier columns split into runs at gaps wider than ``run_gap_m``; each run long, dense and
   strong enough is a line: ends at the 2 % and 98 % quantiles, weighted by ridge value, of the inliers at
   least half the line's median strength; depth along it by a Theil-Sen fit (columns where a crossing
   target lies shallower do not tilt it). The band around an accepted line is removed before the next
   search (an L-shaped pipe becomes two lines, a thick image of one pipe stays one, a bar of a mat crossing
   it keeps the rest of its length); a line lying mostly within two bands of a parallel one already found
   is that line's fringe and is dropped; a Hough peak that gives no line is suppressed, its columns stay
   for the others;
3. an end piece of a line beyond a gap, lying in the band of another line that crosses it, is that line's
   image and is cut off;
4. collinear lines (within 3 deg, their axes within the inlier distance, at one depth) across a gap
   shorter than ``join_gap_m`` are joined into one;
5. what remains of a connected part, if compact, is a point target (weighted centroid).

``benchmarks/eval_scenes.py`` scores this on random forward-model scenes (pipes, rebar mats).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from gpr3d.core.grid import Grid3D

__all__ = ["Target3D", "ridge_map", "extract_targets", "extract_profile_targets", "targets_to_json", "target_name",
           "theil_sen"]


@dataclass
class Target3D:
    kind: str  #: "line" or "point"
    points_xyz: list  #: [[x, y, depth], ...]: the two endpoints of a line, or the point
    depth_m: float  #: depth of the top (shallowest point)
    score: float  #: mean ridge value of its columns / the reference level (see extract_targets)
    n_voxels: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def direction(self) -> np.ndarray | None:
        if self.kind != "line":
            return None
        d = np.subtract(self.points_xyz[1], self.points_xyz[0])
        return d / np.linalg.norm(d)

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(np.subtract(self.points_xyz[1], self.points_xyz[0]))) if self.kind == "line" else 0.0


def _cut_tails(envelope: np.ndarray, k0: int) -> np.ndarray:
    """The envelope from depth cell ``k0`` down, without the tail of what rings above the cut: in each column, the
    cells from ``k0`` on while the envelope still falls from the cell above. A column's maximum in that tail is
    the cut, not a target; left in, the ridge map gets a bright floor at the cut depth that any line can run
    along."""
    below = envelope[:, :, k0:]
    if k0 == 0 or below.shape[2] == 0:
        return below
    falling = np.logical_and.accumulate(below < envelope[:, :, k0 - 1:-1], axis=2)
    return np.where(falling, np.float32(0.0), below)


def ridge_map(envelope: np.ndarray, grid: Grid3D):
    """``(value (nx, ny), depth_m (nx, ny))`` of each column's envelope maximum (parabolic sub-cell depth)."""
    k = np.argmax(envelope, axis=2)
    val = np.take_along_axis(envelope, k[..., None], axis=2)[..., 0]
    km = np.clip(k, 1, envelope.shape[2] - 2)
    y0 = np.take_along_axis(envelope, (km - 1)[..., None], axis=2)[..., 0].astype(float)
    y1 = np.take_along_axis(envelope, km[..., None], axis=2)[..., 0].astype(float)
    y2 = np.take_along_axis(envelope, (km + 1)[..., None], axis=2)[..., 0].astype(float)
    den = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where((den < 0) & (k == km), 0.5 * (y0 - y2) / den, 0.0)
    return val, grid.d0 + (k + np.clip(delta, -0.5, 0.5)) * grid.dd


def _line_dist(p, c, d):
    r = p - c
    return np.abs(r[:, 0] * d[1] - r[:, 1] * d[0])


def _pca(p, w):
    c = np.average(p, axis=0, weights=w)
    q = (p - c) * np.sqrt(w)[:, None]
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    return c, vt[0]


def _extent(s, w, q):
    """The extent along a line of its inlier columns (positions ``s``): the ``q`` and ``1 - q`` quantiles of ``s``
    weighted by the columns' ridge values ``w`` (weak columns at the ends, the smear past a pipe's end, count for
    little); ``q = 0`` gives the unweighted 1st and 99th percentiles."""
    if q <= 0:
        lo, hi = np.percentile(s, [1, 99])
        return float(lo), float(hi)
    order = np.argsort(s)
    cw = np.cumsum(w[order])
    cw /= cw[-1]
    return float(s[order][np.searchsorted(cw, q)]), float(s[order][min(np.searchsorted(cw, 1 - q), len(s) - 1)])


def join_collinear(lines: list, *, tol_m: float, join_gap_m: float, max_angle_deg: float = 3.0) -> list:
    """Join line targets that continue one another: directions within ``max_angle_deg``, each one's ends within
    ``tol_m`` (horizontally) of the other's axis and depth, the gap between them under ``join_gap_m``."""
    out = [t for t in lines]
    merged = True
    while merged:
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                a, b = out[i], out[j]
                pa, pb = np.array(a.points_xyz, float), np.array(b.points_xyz, float)
                da = (pa[1, :2] - pa[0, :2]) / max(np.linalg.norm(pa[1, :2] - pa[0, :2]), 1e-12)
                db = (pb[1, :2] - pb[0, :2]) / max(np.linalg.norm(pb[1, :2] - pb[0, :2]), 1e-12)
                if abs(float(da @ db)) < np.cos(np.radians(max_angle_deg)):
                    continue
                # b's ends against a's axis (horizontal offset) and a's depth line, extended
                sa = (pb[:, :2] - pa[0, :2]) @ da
                off = np.abs((pb[:, 0] - pa[0, 0]) * da[1] - (pb[:, 1] - pa[0, 1]) * da[0])
                la = float(np.linalg.norm(pa[1, :2] - pa[0, :2]))
                dep_a = pa[0, 2] + (pa[1, 2] - pa[0, 2]) * sa / max(la, 1e-12)
                if off.max() > tol_m or np.abs(pb[:, 2] - dep_a).max() > tol_m:
                    continue
                gap = max(sa.min() - la, -sa.max(), 0.0)
                if gap > join_gap_m:
                    continue
                ends = np.vstack([pa, pb])
                s_all = (ends[:, :2] - pa[0, :2]) @ da
                k0, k1 = int(np.argmin(s_all)), int(np.argmax(s_all))
                na, nb_ = a.n_voxels, b.n_voxels
                joined = Target3D("line", [ends[k0].tolist(), ends[k1].tolist()], float(min(ends[k0][2], ends[k1][2])),
                                  float((a.score * na + b.score * nb_) / max(na + nb_, 1)), na + nb_,
                                  {"joined": a.extra.get("joined", 1) + b.extra.get("joined", 1)})
                out = [t for k, t in enumerate(out) if k not in (i, j)] + [joined]
                merged = True
                break
            if merged:
                break
    return out


def _fringe(a, b, found, band, max_angle_deg: float = 10.0) -> bool:
    """True when most of segment a-b (horizontal) lies within ``band`` of a near-parallel line already found:
    the fringe of that line's (wide) image, not a target of its own."""
    u = (b - a) / max(np.hypot(*(b - a)), 1e-12)
    pts = a + np.linspace(0.0, 1.0, 11)[:, None] * (b - a)
    for t in found:
        pa, pb = np.array(t.points_xyz[0][:2]), np.array(t.points_xyz[1][:2])
        v = (pb - pa) / max(np.hypot(*(pb - pa)), 1e-12)
        if abs(float(u @ v)) >= np.cos(np.radians(max_angle_deg)) and np.mean(_seg_dists(pts, pa, pb) < band) >= 0.7:
            return True
    return False


def _seg_dists(q, a, b):
    ab = b - a
    t = np.clip((q - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.hypot(*(q - (a + t[:, None] * ab)).T)


def _side_level(val, grid, a, b, offset) -> float:
    """How bright the map stays beside segment a-b: on each side, the dimmer of the mean ridge values along the
    parallels ``offset`` and ``2 offset`` away (inside the map); the brighter side's. A pipe is dim on both sides
    (a parallel pipe close by is bright at one distance only); a bright layer through or along the line is not."""
    d = (b - a) / max(np.hypot(*(b - a)), 1e-12)
    n = np.array([-d[1], d[0]])
    t = np.linspace(0.0, 1.0, max(int(np.hypot(*(b - a)) / min(grid.dx, grid.dy)), 2))
    pts = a + t[:, None] * (b - a)
    sides = []
    for side in (-1.0, 1.0):
        levels = []
        for k in (1.0, 2.0):
            q = pts + side * k * offset * n
            i = np.rint((q[:, 0] - grid.x0) / grid.dx).astype(int)
            j = np.rint((q[:, 1] - grid.y0) / grid.dy).astype(int)
            ok = (i >= 0) & (i < val.shape[0]) & (j >= 0) & (j < val.shape[1])
            if ok.any():
                levels.append(float(val[i[ok], j[ok]].mean()))
        if levels:
            sides.append(min(levels))
    return float(max(sides)) if sides else 0.0


def theil_sen(x, y) -> tuple[float, float]:
    """Slope and intercept of the Theil-Sen line through the points ``(x, y)``: the median of the slopes between
    every two points with different ``x``, and the median of ``y`` less the slope times the median of ``x`` (what
    ``scipy.stats.theilslopes`` gives by its default "separate" method; scipy.stats takes half a second to import,
    more than a whole reconstruction's target extraction)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    dx = x[None, :] - x[:, None]
    up = dx > 0
    if not up.any():
        raise ValueError("a Theil-Sen slope needs two points with different x")
    slope = float(np.median((y[None, :] - y[:, None])[up] / dx[up]))
    return slope, float(np.median(y) - slope * np.median(x))


def _depth_fit(s, depth, w, dd):
    """Depth along a line, ``depth = k s + m``: Theil-Sen (robust to the columns where a crossing target lies
    shallower), then a weighted least-squares fit to the columns within ``max(2 dd, median residual)``."""
    if len(s) < 3 or np.ptp(s) <= 0:
        return np.array([0.0, float(np.average(depth, weights=w))])
    k, m = theil_sen(s, depth)
    A = np.stack([s, np.ones_like(s)], axis=1)
    res = np.abs(A @ np.array([k, m]) - depth)
    keep = res <= max(2 * dd, float(np.median(res)))
    coef, *_ = np.linalg.lstsq(A[keep] * w[keep, None], depth[keep] * w[keep], rcond=None)
    return coef


def _is_line(s, n, min_line, min_density, cell):
    # a real line's image is at least a cell wide all along: sparse "lines" join scattered blobs
    return s[-1] - s[0] >= min_line and n * cell / max(s[-1] - s[0], 1e-9) >= min_density


def _chain_runs(s, w, depth, *, run_gap, join_gap, min_columns, min_line, min_density, cell, level, depth_tol):
    """The runs of a Hough line's inliers (positions ``s`` along it, sorted) that make lines: split at gaps over
    ``run_gap``; a run long and dense enough is a line, and takes in the short pieces beyond its ends (each
    within ``join_gap`` of the last, at least ``level`` strong on average, at its depth within ``depth_tol``):
    a rebar imaged as bright stretches between the bars crossing it stays one line."""
    runs = [r for r in np.split(np.arange(len(s)), np.nonzero(np.diff(s) > run_gap)[0] + 1) if len(r) >= min_columns]
    ok = [_is_line(s[r], len(r), min_line, min_density, cell) for r in runs]
    used = [False] * len(runs)
    out = []
    for k, r in enumerate(runs):
        if not ok[k] or used[k]:
            continue
        used[k] = True
        chain = [r]
        zd = float(np.median(depth[r]))
        for step in (-1, 1):
            j, edge = k + step, (r[0] if step < 0 else r[-1])
            while 0 <= j < len(runs) and not ok[j] and not used[j]:
                q = runs[j]
                gap = s[edge] - s[q[-1]] if step < 0 else s[q[0]] - s[edge]
                if gap > join_gap or w[q].mean() < level or abs(float(np.median(depth[q])) - zd) > depth_tol:
                    break
                used[j] = True
                chain.append(q)
                edge = q[0] if step < 0 else q[-1]
                j += step
        out.append(np.sort(np.concatenate(chain)))
    return out


class _Hough:
    """Weighted Hough accumulator over points ``p (n, 2)`` (m) with weights ``w``: angle steps of ``step_deg``,
    distance bins of ``tol``. Points can be removed (their votes subtracted) and peaks suppressed."""

    def __init__(self, p, w, tol, step_deg):
        self.p, self.w, self.tol = p, w, tol
        th = np.radians(np.arange(0.0, 180.0, step_deg))
        self.normals = np.stack([np.cos(th), np.sin(th)], axis=1)
        self.centre = p.mean(axis=0)
        self.rmax = float(np.hypot(*(p - self.centre).T).max()) + tol
        self.nr = int(np.ceil(2 * self.rmax / tol)) + 1
        self.acc = self._votes(np.arange(len(p)))
        self.suppressed = np.zeros(self.acc.shape, bool)

    def _votes(self, idx):
        nth = len(self.normals)
        r = (self.p[idx] - self.centre) @ self.normals.T
        rb = np.clip(np.floor((r + self.rmax) / self.tol).astype(np.int64), 0, self.nr - 1)
        flat = (rb + self.nr * np.arange(nth)[None, :]).ravel()
        return np.bincount(flat, np.repeat(self.w[idx], nth), minlength=self.nr * nth).reshape(nth, self.nr)

    def remove(self, idx):
        if len(idx):
            self.acc -= self._votes(idx)

    def peak(self):
        """``(votes, centre, direction, (angle bin, distance bin))`` of the strongest line not suppressed (a
        line straddling two distance bins counts both)."""
        sm = self.acc.copy()
        sm[:, :-1] += self.acc[:, 1:]
        sm[self.suppressed] = -np.inf
        ti, ri = np.unravel_index(int(np.argmax(sm)), sm.shape)
        n = self.normals[ti]
        c = self.centre + ((ri + 1) * self.tol - self.rmax) * n
        return float(sm[ti, ri]), c, np.array([-n[1], n[0]]), (ti, ri)

    def suppress(self, key):
        ti, ri = key
        self.suppressed[np.arange(ti - 2, ti + 3) % len(self.normals), max(ri - 1, 0):ri + 2] = True


def _trim_crossings(lines, info, P, W, band, end_weight, end_rel, min_angle_deg: float = 20.0):
    """Cut off a line's end piece (beyond a gap wider than ``band``) whose columns lie mostly within ``band`` of
    another line crossing it (at more than ``min_angle_deg``): that line's image, not this one's."""
    geo = [(np.array(t.points_xyz[0][:2]), np.array(t.points_xyz[1][:2])) for t in lines]
    for i, t in enumerate(lines):
        cols, c, d, coef = info[i]
        s = (P[cols] - c) @ d
        order = np.argsort(s)
        cols, s = cols[order], s[order]
        claimed = np.zeros(len(cols), bool)
        for j, (pa, pb) in enumerate(geo):
            v = (pb - pa) / max(np.hypot(*(pb - pa)), 1e-12)
            if j != i and abs(float(v @ d)) <= np.cos(np.radians(min_angle_deg)):
                claimed |= _seg_dists(P[cols], pa, pb) < band
        pieces = np.split(np.arange(len(cols)), np.nonzero(np.diff(s) > band)[0] + 1)
        k0, k1 = 0, len(pieces)
        if k1 - k0 > 1 and claimed[pieces[k0]].mean() >= 0.5:
            k0 += 1
        if k1 - k0 > 1 and claimed[pieces[k1 - 1]].mean() >= 0.5:
            k1 -= 1
        if (k0, k1) == (0, len(pieces)):
            continue
        keep = np.concatenate(pieces[k0:k1])
        ss, ww = s[keep], W[cols[keep]]
        strong = ww >= end_rel * np.median(ww)
        lo, hi = _extent(ss[strong], ww[strong], end_weight)
        a = np.append(c + lo * d, coef[0] * lo + coef[1])
        b = np.append(c + hi * d, coef[0] * hi + coef[1])
        t.points_xyz = [a.tolist(), b.tolist()]
        t.depth_m = float(min(a[2], b[2]))
        t.extra["trimmed"] = True


def extract_targets(envelope: np.ndarray, grid: Grid3D, *, threshold: float = 0.3, reference_percentile: float = 99.5,
                    min_line_m: float = 0.3, tol_m: float | None = None, band_m: float | None = None,
                    min_columns: int = 6, min_density: float = 1.0, line_contrast: float = 4.0 / 3.0,
                    group_gap_m: float | None = None, run_gap_m: float | None = None, join_gap_m: float = 0.5,
                    end_weight: float = 0.02, end_rel: float = 0.5, max_segments: int = 40,
                    angle_step_deg: float = 0.5, max_peaks: int = 400, min_depth_m: float | None = None,
                    max_dip_deg: float = 45.0, lateral_contrast: float = 1.5) -> list[Target3D]:
    """Line and point targets from an image envelope ``(nx, ny, nd)`` on ``grid`` (deterministic).

    ``threshold`` is relative to the ``reference_percentile`` of the ridge map (a robust stand-in for its
    maximum: pipe ends and crossings make hot spots far brighter than the pipes themselves). ``tol_m`` (default
    2 cells) is the inlier distance of the line fits and the Hough bin; ``band_m`` (default ``max(4 tol, 0.1 m)``;
    ``reconstruct`` gives ``max(2 tol, half a wavelength)``) the band removed around an accepted line. Columns
    whose gaps are narrower than ``group_gap_m`` (default 3 bands) are searched together; a line's inliers split
    at gaps wider than ``run_gap_m`` (default 4 bands, at most 0.5 m). A line needs ``min_line_m`` of length (shorter: points),
    ``min_density`` inlier columns per cell of its length, and a mean ridge value of ``line_contrast`` x the
    threshold (a smear just above the threshold is not a pipe). Its ends: the ``end_weight`` and
    ``1 - end_weight`` quantiles, weighted by ridge value, of its inlier columns at least ``end_rel`` times their
    median value. Collinear lines across gaps up to ``join_gap_m`` are joined. A line must stand out from its
    sides (its mean ridge value ``lateral_contrast`` times the level 2.5 and 5 bands to the brighter side, see
    ``_side_level``: a dipping layer's image is bright beside a line through it, a pipe's is not) and dip
    less than ``max_dip_deg``. ``min_depth_m``: nothing shallower is looked at (e.g. where the direct wave
    rings). At most ``max_segments`` lines and ``max_peaks`` Hough peaks per group are examined.
    """
    envelope = np.asarray(envelope, dtype=np.float32)
    if min_depth_m is not None and min_depth_m > grid.d0:
        k0 = min(int(np.ceil((min_depth_m - grid.d0) / grid.dd - 1e-9)), grid.nd - 1)
        envelope = _cut_tails(envelope, k0)
        grid = replace(grid, d0=grid.d0 + k0 * grid.dd, nd=grid.nd - k0)
    val, dep = ridge_map(envelope, grid)
    peak = float(np.percentile(val, reference_percentile))
    if not peak > 0:
        return []
    cell = min(grid.dx, grid.dy)
    tol = tol_m or 2.0 * max(grid.dx, grid.dy)
    band = band_m or max(4 * tol, 0.1)
    group_gap = 3 * band if group_gap_m is None else group_gap_m
    run_gap = min(4 * band, 0.5) if run_gap_m is None else run_gap_m
    mask = val >= threshold * peak
    parts, n_parts = ndimage.label(mask, structure=np.ones((3, 3)))
    r = int(round(group_gap / 2 / cell))
    if r > 0:
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        grown = ndimage.binary_dilation(mask, structure=(xx**2 + yy**2) <= r * r)
    else:
        grown = mask
    groups, n_groups = ndimage.label(grown, structure=np.ones((3, 3)))
    idx = np.argwhere(mask)
    P = np.stack([grid.x0 + idx[:, 0] * grid.dx, grid.y0 + idx[:, 1] * grid.dy], axis=1)
    W = val[tuple(idx.T)].astype(float)
    D = dep[tuple(idx.T)].astype(float)
    part_of, group_of = parts[tuple(idx.T)], groups[tuple(idx.T)]
    left = np.ones(len(P), bool)  # not explained by a line (candidates for points)
    lines: list[Target3D] = []
    info = []  # per line: (its columns, centre, direction, depth fit), for trimming
    for g in range(1, n_groups + 1):
        members = np.nonzero(group_of == g)[0]
        if len(members) < min_columns:
            continue
        p, w = P[members], W[members]
        hough = _Hough(p, w, tol, angle_step_deg)
        avail = np.ones(len(p), bool)
        for _ in range(max_peaks):
            if avail.sum() < min_columns or len(lines) >= max_segments:
                break
            votes, c0, d0, key = hough.peak()
            if votes < min_columns * threshold * peak:
                break  # no line of min_columns columns left
            sel = np.nonzero(avail)[0]
            inl = _line_dist(p[sel], c0, d0) < tol
            if inl.sum() < min_columns:
                hough.suppress(key)
                continue
            c, d = _pca(p[sel][inl], w[sel][inl])
            inl = _line_dist(p[sel], c, d) < tol
            if inl.sum() >= 2:
                c, d = _pca(p[sel][inl], w[sel][inl])
                inl = _line_dist(p[sel], c, d) < tol
            ii = sel[inl]
            s = (p[ii] - c) @ d
            order = np.argsort(s)
            ii, s = ii[order], s[order]
            cleared = np.zeros(len(p), bool)
            runs = _chain_runs(s, w[ii], D[members[ii]], run_gap=run_gap, join_gap=join_gap_m, min_columns=min_columns,
                               min_line=min_line_m, min_density=min_density, cell=cell,
                               level=line_contrast * threshold * peak, depth_tol=max(2 * grid.dd, tol))
            for run in runs:
                jj, ss, ww = ii[run], s[run], w[ii[run]]
                strong = ww >= end_rel * np.median(ww)
                lo, hi = _extent(ss[strong], ww[strong], end_weight)
                # as bright beside it as on it (a dipping layer), or plunging: no pipe; its columns stay (the first
                # test needs only the ends' x, y: on a noisy record most runs fail it, and skip the depth fit)
                if _side_level(val, grid, c + lo * d, c + hi * d, 2.5 * band) * lateral_contrast > ww.mean():
                    continue
                coef = _depth_fit(ss, D[members[jj]], ww, grid.dd)
                if abs(coef[0]) > np.tan(np.radians(max_dip_deg)):
                    continue
                a = np.append(c + lo * d, coef[0] * lo + coef[1])
                b = np.append(c + hi * d, coef[0] * hi + coef[1])
                if ww.mean() >= line_contrast * threshold * peak and not _fringe(a[:2], b[:2], lines, 2 * band):
                    lines.append(Target3D("line", [a.tolist(), b.tolist()], float(min(a[2], b[2])),
                                          float(ww.mean() / peak), int(len(run))))
                    info.append((members[jj], c, d, coef))
                along = (p - c) @ d
                cleared |= (_line_dist(p, c, d) < band) & (along >= lo - band) & (along <= hi + band)
            if not cleared.any():
                hough.suppress(key)  # this peak gives no line; its columns stay for other lines
                continue
            gone = np.nonzero(cleared & avail)[0]
            avail[gone] = False
            left[members[cleared]] = False
            hough.remove(gone)
    _trim_crossings(lines, info, P, W, band, end_weight, end_rel)
    points: list[Target3D] = []
    for lab in range(1, n_parts + 1):
        sel = np.nonzero(left & (part_of == lab))[0]
        if len(sel) < min_columns:
            continue
        w = W[sel]
        # only a compact, strong remainder is a point target
        cen = np.average(P[sel], axis=0, weights=w)
        spread = np.sqrt(np.average(np.sum((P[sel] - cen) ** 2, axis=1), weights=w))
        if spread < max(min_line_m / 2, 3 * tol):
            k = sel[np.argmax(w)]
            points.append(Target3D("point", [[float(cen[0]), float(cen[1]), float(D[k])]], float(D[k]),
                                   float(w.mean() / peak), int(len(sel))))
    out = join_collinear(lines, tol_m=tol, join_gap_m=join_gap_m) + points
    out.sort(key=lambda t: -t.score * t.n_voxels)
    return out


def extract_profile_targets(envelope: np.ndarray, along_m: np.ndarray, depth_m: np.ndarray, *,
                            threshold: float = 0.3, reference_percentile: float = 99.5, min_line_m: float = 0.3,
                            line_contrast: float = 4.0 / 3.0, min_columns: int = 2, end_weight: float = 0.02,
                            end_rel: float = 0.5, min_depth_m: float | None = None) -> list[Target3D]:
    """Targets in one migrated profile ``envelope (n_along, n_depth)``: what a 3D reconstruction of a single
    straight line falls back to. Coordinates are ``[along, 0, depth]`` (the caller maps them to the world).

    The image's parts above ``threshold`` x the ``reference_percentile`` of its column maxima (as
    :func:`extract_targets`' ridge map) are targets: a part that is at least ``min_line_m`` long, not steeper than
    45 deg and whose columns' mean maximum reaches ``line_contrast`` x the threshold is a line in the profile's
    plane (a pipe along the line, or a layer; ends and depth as for 3D lines); a shorter one of at least
    ``min_columns`` columns is a point (a target crossing the profile) at its maximum, refined to sub-cell along
    and in depth by parabolas.
    """
    env = np.asarray(envelope, dtype=np.float32)
    along_m = np.asarray(along_m, float)
    depth_m = np.asarray(depth_m, float)
    if env.ndim != 2 or env.shape != (len(along_m), len(depth_m)):
        raise ValueError(f"envelope {env.shape} does not match {len(along_m)} positions x {len(depth_m)} depths")
    if min_depth_m is not None:
        env = np.where(depth_m[None, :] >= min_depth_m - 1e-9, env, 0.0)
    if env.size == 0:
        return []
    cols = env.max(axis=1)
    peak = float(np.percentile(cols, reference_percentile))
    if not peak > 0:
        return []
    dx = float(np.median(np.diff(along_m))) if len(along_m) > 1 else 1.0
    dd = float(np.median(np.diff(depth_m))) if len(depth_m) > 1 else 1.0
    parts, n = ndimage.label(env >= threshold * peak, structure=np.ones((3, 3)))
    out: list[Target3D] = []
    for lab, sl in enumerate(ndimage.find_objects(parts), start=1):
        if sl is None:
            continue
        sub = np.where(parts[sl] == lab, env[sl], 0.0)
        ia = np.arange(sl[0].start, sl[0].stop)
        present = sub.max(axis=1) > 0
        if present.sum() < min_columns:
            continue
        ia, sub = ia[present], sub[present]
        w = sub.max(axis=1).astype(float)
        kd = sl[1].start + np.argmax(sub, axis=1)
        s, dep = along_m[ia], depth_m[kd]
        if s[-1] - s[0] >= min_line_m and w.mean() >= line_contrast * threshold * peak:
            strong = w >= end_rel * np.median(w)
            lo, hi = _extent(s[strong], w[strong], end_weight)
            coef = _depth_fit(s, dep, w, dd)
            if abs(coef[0]) <= 1.0:  # steeper than 45 deg: a hyperbola's unfocused flank, not a reflector
                a, b = [lo, 0.0, coef[0] * lo + coef[1]], [hi, 0.0, coef[0] * hi + coef[1]]
                out.append(Target3D("line", [a, b], float(min(a[2], b[2])), float(w.mean() / peak), int(len(s)),
                                    extra={"profile": True}))
                continue
        # a point: the part's maximum, refined by parabolas through its neighbours (in the full image)
        i, k = np.unravel_index(np.argmax(np.where(parts == lab, env, 0.0)), env.shape)

        def vertex(y0, y1, y2):
            den = y0 - 2 * y1 + y2
            return float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5)) if den < 0 else 0.0

        da = vertex(env[i - 1, k], env[i, k], env[i + 1, k]) if 0 < i < env.shape[0] - 1 else 0.0
        dk = vertex(env[i, k - 1], env[i, k], env[i, k + 1]) if 0 < k < env.shape[1] - 1 else 0.0
        pa, pd = along_m[i] + da * dx, depth_m[k] + dk * dd
        out.append(Target3D("point", [[float(pa), 0.0, float(pd)]], float(pd), float(env[i, k] / peak), int(len(s)),
                            extra={"profile": True}))
    out.sort(key=lambda t: -t.score * t.n_voxels)
    return out


def targets_to_json(targets: list[Target3D]) -> dict:
    """The ``targets.json`` contract of CONVENTIONS.md: each target named ``T1``, ``T2``, ... in list order (the
    names the figures label them with, see :func:`target_name`)."""
    return {"targets": [{"name": target_name(i), "kind": t.kind,
                         "points_xyz": [[float(v) for v in p] for p in t.points_xyz],
                         "depth_m": float(t.depth_m), "score": float(t.score)} for i, t in enumerate(targets)]}


def target_name(index: int) -> str:
    """The name of the target at ``index`` (0-based) of a target list: ``T1``, ``T2``, ... (``targets.json``,
    the reconstruction figures, the CLI's listing and the demo's ``summary.json`` all use it)."""
    return f"T{index + 1}"
