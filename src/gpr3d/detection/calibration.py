"""Detection scores as probabilities: Platt scaling fitted on records the detector never trained on.

A detector's raw score ranks its boxes, but two trainings of one recipe can put the same boxes at 0.6 and at 0.95:
a fixed threshold (``--score 0.5``) then keeps very different shares of false boxes. Platt scaling maps a raw
score ``s`` to ``sigmoid(a * logit(s) + b)``, with ``a > 0`` and ``b`` fitted by maximum likelihood so that, on
held-out records, a box scored ``p`` is a labelled target (one-to-one, IoU >= 0.5: :func:`box_truth`) with
probability ``p``. The map is increasing, so the ranking of boxes, and every COCO metric computed from it, stays
as it was; what changes is which boxes a threshold keeps.

A weights file carries its map in ``provenance["score_calibration"]`` (``{"method": "platt", "a", "b", ...}``,
written by ``references/detection/calibrate_scores.py``); :class:`gpr3d.detection.infer.Detector` applies it to
every score it reports.
"""

from __future__ import annotations

import math

import numpy as np

from gpr3d.core.errors import GPR3DError

__all__ = ["fit_platt", "calibrate", "check_calibration", "box_truth"]

#: raw scores are clipped to [EPS, 1 - EPS] before their logit (a network's 1.0 would be infinite)
EPS = 1e-6


def _logit(scores) -> np.ndarray:
    s = np.clip(np.asarray(scores, np.float64), EPS, 1.0 - EPS)
    return np.log(s) - np.log1p(-s)


def fit_platt(scores, truth, *, iterations: int = 100) -> tuple[float, float]:
    """``(a, b)`` of the Platt map that best explains ``truth`` (booleans, one per score) by maximum likelihood.

    Newton's method on the logistic loss, with a tiny ridge so that perfectly separated scores still give a
    finite map. Needs both true and false boxes; a map that would not increase with the raw score (``a <= 0``:
    the scores say nothing) is refused.
    """
    z = _logit(scores).reshape(-1)
    y = np.asarray(truth, dtype=np.float64).reshape(-1)
    if z.size != y.size:
        raise GPR3DError(f"score calibration: {z.size} scores but {y.size} truth values")
    if not np.isfinite(np.asarray(scores, np.float64)).all():
        raise GPR3DError("score calibration: the scores hold NaN or infinite values")
    n_true = int(y.sum())
    if n_true == 0 or n_true == y.size:
        raise GPR3DError(f"score calibration needs true and false boxes; got {n_true} true of {y.size}")
    x = np.stack([z, np.ones_like(z)], axis=1)
    w = np.zeros(2)
    ridge = 1e-6 * y.size
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-(x @ w)))
        grad = x.T @ (p - y) + ridge * w
        hess = (x * (p * (1.0 - p))[:, None]).T @ x + ridge * np.eye(2)
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.abs(step).max() < 1e-10:
            break
    a, b = float(w[0]), float(w[1])
    if not a > 0.0:
        raise GPR3DError(f"score calibration: the fitted map does not increase with the score (a = {a:.3g}): "
                         "these scores do not rank true boxes above false ones")
    return a, b


def check_calibration(cal, where: str = "score calibration") -> dict | None:
    """``cal`` (a weights file's ``score_calibration``) checked: None, or a Platt map with finite ``a > 0`` and
    ``b``; anything else raises one line naming ``where``."""
    if cal is None:
        return None
    if not isinstance(cal, dict) or cal.get("method") != "platt":
        raise GPR3DError(f"{where}: expected {{'method': 'platt', 'a': ..., 'b': ...}}, got {cal!r:.80}")
    a, b = cal.get("a"), cal.get("b")
    ok = all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in (a, b))
    if not ok or a <= 0:
        raise GPR3DError(f"{where}: a must be a finite number > 0 and b a finite number, got a={a!r}, b={b!r}")
    return cal


def calibrate(scores, cal: dict | None) -> np.ndarray:
    """``scores`` through the Platt map ``cal`` (None: unchanged), as float64."""
    s = np.asarray(scores, np.float64)
    if cal is None or s.size == 0:
        return s.copy()
    return 1.0 / (1.0 + np.exp(-(float(cal["a"]) * _logit(s) + float(cal["b"]))))


def box_truth(found_boxes, found_scores, true_boxes, *, iou: float = 0.5) -> np.ndarray:
    """Per found box, whether it is a labelled target: matched one-to-one, best score first, at IoU >= ``iou``
    (:func:`gpr3d.detection.evaluate.box_matches`, kinds ignored). Boxes in one unit per axis."""
    from gpr3d.detection.evaluate import box_matches

    n = len(found_boxes)
    hits = box_matches(list(true_boxes), [None] * len(true_boxes), list(found_boxes), [None] * n,
                       [float(s) for s in np.ravel(found_scores)], iou=iou)
    ok = np.zeros(n, bool)
    for h in hits:
        if h is not None:
            ok[h[0]] = True
    return ok
