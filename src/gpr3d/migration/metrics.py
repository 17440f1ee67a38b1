"""Reconstructed targets against the true scene: position, depth, orientation, completeness, false targets.

Truth lines are the **tops** of the true pipes (``depth = -z_centre - radius``),
sampled every centimetre. An extracted line covers a truth sample when it passes
within ``tol_m`` (3D) of it and runs within ``max_angle_deg`` of the truth
direction; each extracted line is matched to the truth line it covers most. Point targets within
``tol_m`` of a truth line cover its samples within ``point_cover_m`` of them (a rebar found as a row of
points is found, and those points are not false).

Overshoot is scored twice: the endpoint error (how far the matched lines' extreme ends lie beyond or short of
the true ends, mean of the two ends) and the excess length (extracted line length lying farther than
``excess_m`` from every truth line, summed over the scene, also as a fraction of the true length).
"""

from __future__ import annotations

import numpy as np

__all__ = ["truth_lines_from_pipes", "evaluate_targets"]


def truth_lines_from_pipes(pipes) -> list[dict]:
    """Truth top-lines ``{"p0": [x, y, depth], "p1": ..., "radius_m"}`` from forward-model pipes."""
    out = []
    for p in pipes:
        a = np.array([p.p0[0], p.p0[1], -p.p0[2] - p.radius_m])
        b = np.array([p.p1[0], p.p1[1], -p.p1[2] - p.radius_m])
        out.append({"p0": a.tolist(), "p1": b.tolist(), "radius_m": p.radius_m})
    return out


def _seg_dist(points, a, b):
    ab = b - a
    t = np.clip((points - a) @ ab / max(ab @ ab, 1e-12), 0, 1)
    proj = a + np.outer(t, ab)
    return np.linalg.norm(points - proj, axis=1), proj


def _samples(a, b, step=0.01):
    n = max(int(np.linalg.norm(b - a) / step), 1) + 1
    return a + np.outer(np.linspace(0, 1, n), b - a)


def evaluate_targets(targets, truth: list[dict], *, tol_m: float = 0.1, max_angle_deg: float = 15.0,
                     point_cover_m: float = 0.05, excess_m: float = 0.1) -> dict:
    """Per truth line: matched segments, position error (horizontal, m), depth error (m), orientation error (deg),
    endpoint error (m), completeness; per scene: false lines and points, excess length (m and fraction)."""
    lines = [t for t in targets if t.kind == "line"]
    points = [np.array(t.points_xyz[0], float) for t in targets if t.kind == "point"]
    line_at = [i for i, t in enumerate(targets) if t.kind == "line"]  # index in ``targets`` of lines[k]
    point_at = [i for i, t in enumerate(targets) if t.kind == "point"]
    per_truth = []
    matched = set()
    cover_by = {}
    for ti, tr in enumerate(truth):
        a, b = np.array(tr["p0"]), np.array(tr["p1"])
        u = (b - a) / np.linalg.norm(b - a)
        samp = _samples(a, b)
        covered = np.zeros(len(samp), bool)
        for li, ln in enumerate(lines):
            pa, pb = np.array(ln.points_xyz[0]), np.array(ln.points_xyz[1])
            d = (pb - pa) / np.linalg.norm(pb - pa)
            ang = np.degrees(np.arccos(min(abs(float(u @ d)), 1.0)))
            if ang > max_angle_deg:
                continue
            dist, _ = _seg_dist(samp, pa, pb)
            hit = dist < tol_m
            if hit.any():
                cover_by.setdefault(li, []).append((hit.sum(), ti))
                covered |= hit
        on_it = []
        for pi, q in enumerate(points):  # points on the line cover it around them
            d_line, _ = _seg_dist(q[None], a, b)
            if d_line[0] < tol_m:
                covered |= np.linalg.norm(samp - q, axis=1) < max(point_cover_m, tol_m)
                on_it.append(point_at[pi])
        per_truth.append({"samples": samp, "covered": covered, "points": on_it})
    for li, lst in cover_by.items():
        matched.add(li)
        best_ti = max(lst)[1]
        per_truth[best_ti].setdefault("lines", []).append(li)
    rows = []
    for ti, tr in enumerate(truth):
        a, b = np.array(tr["p0"]), np.array(tr["p1"])
        u = (b - a) / np.linalg.norm(b - a)
        info = per_truth[ti]
        lis = info.get("lines", [])
        row = {"truth": ti, "length_m": float(np.linalg.norm(b - a)), "n_segments": len(lis),
               "completeness": float(info["covered"].mean()),
               # which targets (indices into ``targets``: lines matched to it, points on it) found this one
               "found_as": sorted([line_at[li] for li in lis] + info["points"])}
        if lis:
            pos_err, dep_err, ang_err, wts = [], [], [], []
            for li in lis:
                ln = lines[li]
                pa, pb = np.array(ln.points_xyz[0]), np.array(ln.points_xyz[1])
                d = (pb - pa) / np.linalg.norm(pb - pa)
                pts = _samples(pa, pb)
                # perpendicular offsets from the (infinite) truth line
                rel = pts - a
                along = rel @ u
                inside = (along >= -tol_m) & (along <= np.linalg.norm(b - a) + tol_m)
                if not inside.any():
                    continue
                perp = rel[inside] - np.outer(along[inside], u)
                horiz_u = np.array([u[0], u[1], 0.0])
                horiz_u = horiz_u / (np.linalg.norm(horiz_u) or 1.0)
                side = np.cross([0, 0, 1.0], horiz_u)
                pos_err.append(float(np.mean(np.abs(perp @ side))))
                dep_err.append(float(np.mean(np.abs(perp[:, 2]))))
                ang_err.append(float(np.degrees(np.arccos(min(abs(float(u @ d)), 1.0)))))
                wts.append(int(inside.sum()))
            if wts:
                w = np.asarray(wts, float)
                ends = np.array([(np.array(lines[li].points_xyz[k]) - a) @ u for li in lis for k in (0, 1)])
                length = float(np.linalg.norm(b - a))
                row.update({"position_error_m": float(np.average(pos_err, weights=w)),
                            "depth_error_m": float(np.average(dep_err, weights=w)),
                            "orientation_error_deg": float(np.average(ang_err, weights=w)),
                            "endpoint_error_m": float(0.5 * (abs(ends.min()) + abs(ends.max() - length))),
                            "overshoot_m": float(max(0.0, -ends.min()) + max(0.0, ends.max() - length))})
        rows.append(row)
    false_lines = [i for i in range(len(lines)) if i not in matched]
    false_at = [line_at[i] for i in false_lines]
    # points are false when no truth line passes within tol
    false_points = 0
    for pi, p in enumerate(points):
        dmin = min((_seg_dist(p[None], np.array(tr["p0"]), np.array(tr["p1"]))[0][0] for tr in truth), default=np.inf)
        false_points += int(dmin > tol_m)
        if dmin > tol_m:
            false_at.append(point_at[pi])
    # excess: extracted line length far from every truth line
    excess = 0.0
    for ln in lines:
        pts = _samples(np.array(ln.points_xyz[0]), np.array(ln.points_xyz[1]))
        step = np.linalg.norm(np.subtract(ln.points_xyz[1], ln.points_xyz[0])) / max(len(pts) - 1, 1)
        dmin = np.full(len(pts), np.inf)
        for tr in truth:
            dmin = np.minimum(dmin, _seg_dist(pts, np.array(tr["p0"]), np.array(tr["p1"]))[0])
        excess += float(np.count_nonzero(dmin > excess_m)) * step
    true_len = float(sum(np.linalg.norm(np.subtract(tr["p1"], tr["p0"])) for tr in truth))
    return {"truth": rows, "false_targets": len(false_lines) + false_points, "false_lines": len(false_lines),
            "false_points": false_points, "false": sorted(false_at), "n_extracted": len(targets), "excess_m": excess,
            "true_length_m": true_len, "excess_fraction": excess / true_len if true_len > 0 else 0.0}
