"""Permittivity and depths of a record's detections: DepthNet, the hyperbola fit, or both.

Three methods (``METHODS``), all from the data (time zero from the direct wave):

* ``"net"``: DepthNet alone (:class:`gpr3d.inversion.depthnet.DepthEstimator`): the
  host eps_r as the median over one window per detection, each target's depth.
* ``"fit"``: the classical fit alone: each hyperbola fitted as a point target
  (:func:`gpr3d.inversion.hyperbola.fit_boxes`), the record's eps_r from all of them
  (:func:`gpr3d.inversion.hyperbola.combine_permittivity`), each target's depth
  from its own fit.
* ``"hybrid"``: the network's eps_r refined by the fit where they agree: the fit's record eps_r,
  corrected for its measured bias (``FIT_BIAS``: a point fit reads a cylinder's hyperbola flatter, so
  ``eps_r`` low by about ``radius / (depth + radius)``), is combined with the network's by their
  uncertainties (the fit's widened by its model error ``FIT_MODEL_ERROR``) when it lies within two of the
  network's standard errors, and left out otherwise (``"fit_agrees": false``); each target's depth is the
  network's, rescaled to that eps_r (at a fixed travel time depth goes as ``1 / sqrt(eps_r)``).

With the targets' radius known (``radius_m``: a rebar mesh of one size, a pipe from the drawings), the fit
is a cylinder of that radius (:func:`gpr3d.inversion.hyperbola.fit_hyperbola`), nearly unbiased, and the
hybrid uses ``FIT_BIAS_RADIUS`` and ``FIT_MODEL_ERROR_RADIUS`` instead.

All four constants were measured on the gprMax training twin (``datasets/gprmax_survey_train.h5``, 16 records),
never on the held-out set. On validation records (forward model, seed 2001) the picked apex times gave
depths several times worse than the network's (time zero from the direct wave is the weak link), so the
hybrid keeps the network's depths.
"""

from __future__ import annotations

import math

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["METHODS", "estimate_depths"]

METHODS = ("hybrid", "net", "fit")
#: the record-level fit's mean relative error of eps_r on the gprMax training twin (16 records)
FIT_BIAS = -0.134
#: relative uncertainty added to the fit's (bias-corrected) eps_r before it is combined: its RMS relative
#: error on the same records
FIT_MODEL_ERROR = 0.25
#: the same two for fits with each target's radius given (``python benchmarks/eval_depth_fit.py --survey
#: datasets/gprmax_survey_train.h5 --n 16 --no-example --models point "radius given"``: record eps_r bias, RMS)
FIT_BIAS_RADIUS = -0.022
FIT_MODEL_ERROR_RADIUS = 0.20


def _combine(a, sa, b, sb):
    wa, wb = 1 / sa**2, 1 / sb**2
    return (wa * a + wb * b) / (wa + wb), 1 / math.sqrt(wa + wb)


def estimate_depths(survey, targets: list[dict], *, method: str = "hybrid", estimator=None,
                    trace_spacing_m: float | None = None, radius_m=None) -> dict:
    """Estimates for ``targets`` (``gpr3d detect`` targets: ``box``, optional ``apex_trace``/``apex_time_s``).

    Returns ``{"permittivity": {"eps_r", "sigma_eps_r", "method", "net": {...}, "fit": {...}},
    "targets": [{"depth_m", "sigma_depth_m", "x_m", "eps_r_fit", ...} per target]}``. ``estimator``: a
    loaded :class:`~gpr3d.inversion.depthnet.DepthEstimator` (default: the shipped weights). ``radius_m``:
    the targets' radius when known (m; one for all, or one per target), for the fit.
    """
    from gpr3d.inversion.hyperbola import _radii, combine_permittivity, fit_boxes, trace_positions

    if method not in METHODS:
        raise InvalidDataError(f"unknown depth method {method!r}; choose one of {', '.join(METHODS)}")
    radii = _radii(radius_m, len(targets))  # checked before any work
    known = radius_m is not None
    bias, model_error = (FIT_BIAS_RADIUS, FIT_MODEL_ERROR_RADIUS) if known else (FIT_BIAS, FIT_MODEL_ERROR)
    x = trace_positions(survey, trace_spacing_m)
    boxes = [[float(v) for v in t["box"]] for t in targets]
    apexes = [(t.get("apex_trace"), t.get("apex_time_s")) for t in targets]
    apexes = apexes if all(a[0] is not None and a[1] is not None for a in apexes) else None
    perm = {"method": method}
    net = None
    if method in ("net", "hybrid"):
        if estimator is None:
            from gpr3d.inversion.depthnet import DepthEstimator

            estimator = DepthEstimator.load()
        net = estimator.estimate(survey, boxes, trace_spacing_m=trace_spacing_m)
        perm["net"] = {"eps_r": net["eps_r"], "sigma_eps_r": net["sigma_eps_r"], "n_windows": net["n_windows"]}
    fits = []
    if method in ("fit", "hybrid") and boxes:
        # a point for each target of unknown radius, a cylinder of its radius for the others
        fits = fit_boxes(survey, boxes, apexes=apexes, trace_spacing_m=trace_spacing_m, model="point",
                         radius_m=radii)
        e, s, n = combine_permittivity(fits)
        perm["fit"] = {"eps_r": e, "sigma_eps_r": s, "n_hyperbolas": n,
                       "model": "cylinder, radius given" if known else "point"}
    fit_eps = perm.get("fit", {}).get("eps_r", float("nan"))
    if method == "net":
        eps, sig = net["eps_r"], net["sigma_eps_r"]
    elif method == "fit":
        eps, sig = fit_eps, perm.get("fit", {}).get("sigma_eps_r", float("nan"))
    else:
        eps, sig = net["eps_r"], net["sigma_eps_r"]
        perm["fit_agrees"] = False
        if math.isfinite(fit_eps):
            fc = fit_eps / (1 + bias)
            if abs(fc - eps) <= 2 * sig:
                eps, sig = _combine(eps, sig, fc, math.hypot(perm["fit"]["sigma_eps_r"] / (1 + bias),
                                                             model_error * fc))
                perm["fit_agrees"] = True
    perm.update(eps_r=eps, sigma_eps_r=sig)
    out = []
    for k, t in enumerate(targets):
        trace = t.get("apex_trace", 0.5 * (boxes[k][0] + boxes[k][2]))
        row = {"x_m": float(np.interp(trace, np.arange(x.size), x))}
        f = fits[k] if fits else None
        if f is not None:
            row["fit"] = {"ok": f.ok, "eps_r": f.eps_r, "depth_m": f.depth_m, "sigma_depth_m": f.sigma_depth_m,
                          "apex_time_s": f.apex_time_s, "rms_s": f.rms_s, "n_picks": f.n_picks}
        if net is not None:
            row["depth_m_net"] = net["depth_m"][k]
        if method == "net":
            d, sd = net["depth_m"][k], net["depth_m"][k] * 0.5 * sig / eps
        elif method == "fit":
            d, sd = (f.depth_m, f.sigma_depth_m) if f is not None and f.ok else (float("nan"), float("nan"))
        else:
            d = net["depth_m"][k] * math.sqrt(net["eps_r"] / eps)
            sd = d * 0.5 * sig / eps
        row.update(depth_m=float(d), sigma_depth_m=float(sd))
        out.append(row)
    return {"permittivity": perm, "targets": out}
