"""Targets from a 3D image: a ridge map, connected parts, sequential robust line fits.

Migrated energy focuses on the surface that reflected it, so each image column's
envelope maximum marks the top of whatever lies below that point. Extraction
works on that ridge map (value and depth of the maximum per column):

1. keep the columns above ``threshold`` x the map's maximum; split them into
   connected parts (8-neighbours);
2. in each part, find straight segments one after the other by weighted RANSAC,
   refined by a weighted principal axis; endpoints at the 2 % and 98 % quantiles,
   weighted by the ridge value, of the inliers at least half the line's median
   strength (the weak fringe past a pipe's end counts little; ends still overshoot
   by 10-20 cm, see ``benchmarks/eval_scenes.py``); the depth along the segment
   by a robust linear fit; the band around an accepted segment is removed before
   the next search (an L-shaped pipe becomes two segments,
   a thick image of one pipe stays one, a bar of a mat crossing it keeps the rest of
   its length), and a segment lying wholly within the band of a longer one is dropped
   as its fragment;
3. collinear segments (within 3 deg, their axes within the inlier distance, at one
   depth) across a gap shorter than ``join_gap_m`` are joined into one;
4. what remains, if large enough, is a point target (weighted centroid).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from gpr3d.core.grid import Grid3D

__all__ = ["Target3D", "ridge_map", "extract_targets", "targets_to_json"]


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


def _ransac(p, w, tol, rng, iters):
    best, best_score = None, -1.0
    n = len(p)
    for _ in range(iters):
        i, j = rng.integers(0, n, 2)
        d = p[j] - p[i]
        nd = np.hypot(*d)
        if nd < 3 * tol:
            continue
        inl = _line_dist(p, p[i], d / nd) < tol
        score = float(w[inl].sum())
        if score > best_score:
            best, best_score = inl, score
    return best


def _seg_point_dist(p, a, b):
    ab = b - a
    t = np.clip((p - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    return float(np.hypot(*(p - (a + t * ab))))


def _shadowed(a, b, found, band):
    """True when both ends of segment a-b lie within ``band`` of one longer line already found
    (a fragment of that line's image, e.g. from a bright end or corner)."""
    for t in found:
        if t.kind != "line":
            continue
        pa, pb = np.array(t.points_xyz[0][:2]), np.array(t.points_xyz[1][:2])
        if np.hypot(*(pb - pa)) >= np.hypot(*(b - a)) and max(_seg_point_dist(a, pa, pb),
                                                               _seg_point_dist(b, pa, pb)) < band:
            return True
    return False


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


def extract_targets(envelope: np.ndarray, grid: Grid3D, *, threshold: float = 0.3, reference_percentile: float = 99.5,
                    min_line_m: float = 0.3,
                    tol_m: float | None = None, band_m: float | None = None, min_columns: int = 6,
                    min_density: float = 1.0, join_gap_m: float = 0.5, end_weight: float = 0.02,
                    end_rel: float = 0.5,
                    max_segments: int = 40, iters: int = 300, seed: int = 0) -> list[Target3D]:
    """Line and point targets from an image envelope ``(nx, ny, nd)`` on ``grid``.

    ``threshold`` is relative to the ``reference_percentile`` of the ridge map (a
    robust stand-in for its maximum: pipe ends and crossings make hot spots far
    brighter than the pipes themselves). ``tol_m`` (default 2 cells) is the inlier distance of the line fits; ``band_m`` (default
    ``max(4 tol, 0.1 m)``; ``reconstruct`` gives ``max(2 tol, half a wavelength)``) the band removed around an
    accepted line; segments shorter than ``min_line_m`` become points; a line needs ``min_density`` inlier
    columns per cell of its length; collinear lines across gaps up to ``join_gap_m`` are joined. A line's ends: the
    ``end_weight`` and ``1 - end_weight`` quantiles, weighted by ridge value, of its inlier columns at least
    ``end_rel`` times their median value (``end_weight = 0``: the unweighted 1st and 99th percentiles).
    """
    val, dep = ridge_map(np.asarray(envelope, dtype=np.float32), grid)
    peak = float(np.percentile(val, reference_percentile))
    if peak <= 0:
        return []
    tol = tol_m or 2.0 * max(grid.dx, grid.dy)
    band = band_m or max(4 * tol, 0.1)
    rng = np.random.default_rng(seed)
    labels, n = ndimage.label(val >= threshold * peak, structure=np.ones((3, 3)))
    out: list[Target3D] = []
    for lab in range(1, n + 1):
        idx = np.argwhere(labels == lab)
        if len(idx) < min_columns:
            continue
        p_all = np.stack([grid.x0 + idx[:, 0] * grid.dx, grid.y0 + idx[:, 1] * grid.dy], axis=1)
        w_all = val[tuple(idx.T)].astype(float)
        d_all = dep[tuple(idx.T)].astype(float)
        left = np.ones(len(idx), bool)
        for _ in range(max_segments):
            if left.sum() < min_columns:
                break
            sel = np.nonzero(left)[0]
            p, w = p_all[sel], w_all[sel]
            inl = _ransac(p, w, tol, rng, iters)
            if inl is None or inl.sum() < min_columns:
                break
            c, d = _pca(p[inl], w[inl])
            inl = _line_dist(p, c, d) < tol
            c, d = _pca(p[inl], w[inl])
            s = (p[inl] - c) @ d
            strong = w[inl] >= end_rel * np.median(w[inl])  # the line's own weak fringe does not set its ends
            lo, hi = _extent(s[strong], w[inl][strong], end_weight)
            if hi - lo < min_line_m:
                break  # no more lines in this part: the rest are points
            # depth along the line: robust straight-line fit (median of depths in slices)
            dd = d_all[sel][inl]
            A = np.stack([s, np.ones_like(s)], axis=1)
            coef, *_ = np.linalg.lstsq(A * w[inl][:, None], dd * w[inl], rcond=None)
            res = np.abs(A @ coef - dd)
            keep = res <= np.percentile(res, 80)
            coef, *_ = np.linalg.lstsq(A[keep], dd[keep], rcond=None)
            a = np.append(c + lo * d, coef[0] * lo + coef[1])
            b = np.append(c + hi * d, coef[0] * hi + coef[1])
            # a real line's image is at least a cell wide all along: sparse "lines" join scattered blobs
            dense = inl.sum() * min(grid.dx, grid.dy) / max(hi - lo, 1e-9) >= min_density
            if dense and not _shadowed(a[:2], b[:2], out, band):
                out.append(Target3D("line", [a.tolist(), b.tolist()], float(min(a[2], b[2])),
                                    float(w[inl].mean() / peak), int(inl.sum())))
            # remove the band around the accepted segment
            along = (p - c) @ d
            near = (_line_dist(p, c, d) < band) & (along >= lo - band) & (along <= hi + band)
            left[sel[near]] = False
        if left.sum() >= min_columns:
            sel = np.nonzero(left)[0]
            w = w_all[sel]
            # only a compact, strong remainder is a point target
            cen = np.average(p_all[sel], axis=0, weights=w)
            spread = np.sqrt(np.average(np.sum((p_all[sel] - cen) ** 2, axis=1), weights=w))
            if spread < max(min_line_m / 2, 3 * tol):
                k = sel[np.argmax(w)]
                out.append(Target3D("point", [[float(cen[0]), float(cen[1]), float(d_all[k])]], float(d_all[k]),
                                    float(w.mean() / peak), int(len(sel))))
    lines = join_collinear([t for t in out if t.kind == "line"], tol_m=tol, join_gap_m=join_gap_m)
    out = lines + [t for t in out if t.kind != "line"]
    out.sort(key=lambda t: -t.score * t.n_voxels)
    return out


def targets_to_json(targets: list[Target3D]) -> dict:
    """The ``targets.json`` contract of CONVENTIONS.md."""
    return {"targets": [{"kind": t.kind, "points_xyz": [[float(v) for v in p] for p in t.points_xyz],
                         "depth_m": float(t.depth_m), "score": float(t.score)} for t in targets]}
