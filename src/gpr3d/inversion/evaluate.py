"""Judging permittivity and depth estimates against labelled records (``gpr3d eval depth``).

For every labelled record (packed dataset or ``gpr3d simulate`` folder) the three
methods of :func:`gpr3d.inversion.estimate.estimate_depths` run on the labelled boxes
(with their apexes: the estimates alone are judged, not the detector). Scores: the
record's eps_r against the truth (MAE, MAPE), and each target's depth to top (MAE in
metres, relative error), by target kind and by depth range.
"""

from __future__ import annotations

import collections
import math

import numpy as np

from gpr3d.inversion.estimate import METHODS, estimate_depths

__all__ = ["depth_rows", "depth_table", "DEPTH_RANGES"]

DEPTH_RANGES = ((0.0, 0.3), (0.3, 1.0), (1.0, math.inf))


def depth_rows(records, *, estimator=None, methods=METHODS) -> list[dict]:
    """One row per (record, method, target): truth and estimate. ``records`` yields ``(Survey, labels)``."""
    rows = []
    for r, (survey, lab) in enumerate(records):
        vis = [x for x in lab["labels"] if x.get("visible", True)]
        if not vis:
            continue
        for m in methods:
            res = estimate_depths(survey, vis, method=m, estimator=estimator)
            for x, t in zip(vis, res["targets"]):
                rows.append({"record": r, "method": m, "kind": x["kind"], "depth_true": float(x["depth_m"]),
                             "eps_true": float(lab["eps_r"]), "eps": float(res["permittivity"]["eps_r"]),
                             "depth": float(t["depth_m"])})
    return rows


def _stats(rows):
    ok = [r for r in rows if math.isfinite(r["depth"]) and math.isfinite(r["eps"])]
    if not ok:
        return len(rows), 0, math.nan, math.nan, math.nan, math.nan
    recs = {}
    for r in ok:  # eps_r is one per record: score each record once
        recs[(r["record"], r["method"])] = (r["eps"], r["eps_true"])
    e = np.array(list(recs.values()))
    err = np.array([abs(r["depth"] - r["depth_true"]) for r in ok])
    rel = np.array([abs(r["depth"] - r["depth_true"]) / max(r["depth_true"], 1e-3) for r in ok])
    return (len(rows), len(ok), float(np.mean(np.abs(e[:, 0] - e[:, 1]))),
            float(np.mean(np.abs(e[:, 0] - e[:, 1]) / e[:, 1])), float(np.mean(err)), float(np.mean(rel)))


def depth_table(rows) -> list[str]:
    """Markdown table lines: per method, all targets, by kind and by depth range."""
    out = ["| method | targets | n | estimated | eps_r MAE | eps_r MAPE | depth MAE m | depth rel. error |",
           "|---|---|---|---|---|---|---|---|"]
    methods = [m for m in METHODS if any(r["method"] == m for r in rows)]
    for m in methods:
        mine = [r for r in rows if r["method"] == m]
        groups = collections.OrderedDict([("all", mine)])
        for lo, hi in DEPTH_RANGES:
            groups[f"top {lo:g}-{hi:g} m" if math.isfinite(hi) else f"top > {lo:g} m"] = \
                [r for r in mine if lo <= r["depth_true"] < hi]
        for kind in sorted({r["kind"] for r in mine}):
            groups[kind] = [r for r in mine if r["kind"] == kind]
        for name, g in groups.items():
            if not g:
                continue
            n, k, mae, mape, dmae, drel = _stats(g)
            out.append(f"| {m} | {name} | {n} | {k} | {mae:.3f} | {100 * mape:.1f} % | {dmae:.4f} | "
                       f"{100 * drel:.1f} % |")
    return out
