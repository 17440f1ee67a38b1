"""The middle stages: hyperbolas found (or read from a file), the host permittivity and each target's depth."""

from __future__ import annotations

import math
import warnings

from gpr3d.core.errors import GPR3DError

__all__ = ["add_depths", "load_models", "read_targets", "targets_from_file"]


def load_models(*, detector: bool = True, depth: str = "hybrid", weights=None, depthnet=None, device: str = "cpu",
                runtime: str = "auto", refiner="auto"):
    """The detector and DepthNet a run needs, loaded (a wrong file fails here, in one line, before any work).

    Parameters
    ----------
    detector : bool
        Load the hyperbola detector.
    depth : {"hybrid", "net", "fit", "none"}
        How depths are estimated: DepthNet is loaded for ``hybrid`` and ``net``.
    weights, depthnet : str or Path, optional
        Their weights (default: the shipped ones).
    device : str
        ``cpu``, ``cuda`` or ``cuda:N``.
    runtime : {"auto", "torch", "onnx", "int8"}
        The detector's runtime (``gpr3d.detection.infer.ENGINES``).
    refiner : str or Path or None
        The detector's box refiner (``load_detector``'s: ``"auto"``, ``"none"`` or a file).

    Returns
    -------
    (Detector or None, DepthEstimator or None)
    """
    from gpr3d.core.timing import stage

    det = net = None
    with stage("load models"):
        if detector:
            from gpr3d.detection.infer import load_detector

            det = load_detector(weights, device=device, engine=runtime, refiner=refiner)
        if depth in ("hybrid", "net"):
            from gpr3d.inversion.depthnet import DepthEstimator

            net = DepthEstimator.load(depthnet, device=device)
    return det, net


def add_depths(survey, result: dict, method: str, depthnet=None, trace_spacing_m: float | None = None,
               radius_m: float | None = None) -> None:
    """Put the host eps_r and each target's depth and position into a detection result, in place.

    Parameters
    ----------
    survey : Survey
        The record the targets were found in.
    result : dict
        A detection result (``Detector.detect``: ``input``, ``targets``); gains ``permittivity``, and each target
        ``x_m``, ``depth_m``, ``sigma_depth_m`` (None where no depth came out).
    method : {"hybrid", "net", "fit"}
        DepthNet refined by the hyperbola fit, DepthNet alone, or the fit alone.
    depthnet : DepthEstimator, optional
        For ``hybrid`` and ``net``.
    trace_spacing_m : float, optional
        The trace spacing where the file has no positions.
    radius_m : float, optional
        The targets' radius when known (the fit then takes a cylinder).

    Warns
    -----
    UserWarning
        When the record has no trace positions and no spacing is given (nothing is added).
    """
    from gpr3d.inversion.estimate import estimate_depths

    if trace_spacing_m is None and survey.distances_m is None:
        warnings.warn(f"{result['input']}: the file has no trace positions; no depths or eps_r "
                      "(give --trace-spacing)", stacklevel=2)
        return
    if not result["targets"] and method == "fit":
        return
    est = estimate_depths(survey, result["targets"], method=method, estimator=depthnet,
                          trace_spacing_m=trace_spacing_m, radius_m=radius_m)
    p = est["permittivity"]
    result["permittivity"] = {"eps_r": p["eps_r"], "sigma_eps_r": p["sigma_eps_r"], "method": method,
                              **{k: p[k] for k in ("net", "fit") if k in p}}
    for t, e in zip(result["targets"], est["targets"]):
        t["x_m"] = e["x_m"]
        t["depth_m"] = e["depth_m"] if math.isfinite(e["depth_m"]) else None
        t["sigma_depth_m"] = e["sigma_depth_m"] if math.isfinite(e["sigma_depth_m"]) else None


def targets_from_file(path, targets, survey) -> list[dict]:
    """Targets read from a detections file, checked against the record they are to be used on.

    Parameters
    ----------
    path : str or Path
        The file (named in the error).
    targets : list of dict
        Its targets (``box`` each; ``apex_trace``, ``apex_time_s`` optional).
    survey : Survey

    Returns
    -------
    list of dict
        Boxes reaching past the record cut to it; an apex that is not a pair of finite numbers dropped (the box's
        own is used).

    Raises
    ------
    GPR3DError
        One line naming the file and its first bad box.
    """
    from gpr3d.migration.masking import check_boxes

    try:
        boxes = check_boxes([t["box"] for t in targets], survey.n_traces, survey.n_samples * survey.dt_s)
    except GPR3DError as exc:
        raise GPR3DError(f"{path}: {exc}") from None
    out = []
    n, window = survey.n_traces, (survey.n_samples - 1) * survey.dt_s
    for t, b in zip(targets, boxes):
        t = dict(t, box=[max(b[0], 0.0), max(b[1], 0.0), min(b[2], n - 1.0), min(b[3], window)])
        a = (t.get("apex_trace"), t.get("apex_time_s"))
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in a):
            t.pop("apex_trace", None)
            t.pop("apex_time_s", None)
        out.append(t)
    return out


def read_targets(path, survey, *, channel: int = 0, input_name=None) -> dict:
    """A detections file (``gpr3d detect`` output) as a detection result for ``survey``, its boxes checked.

    Parameters
    ----------
    path : str or Path
        The detections file (``detections.json``).
    survey : Survey
        The record the boxes must lie in.
    channel : int
        Which channel of the file.
    input_name : str, optional
        The record's name in the result (default: ``path``).

    Returns
    -------
    dict
        ``{"input": name, "targets": [...]}``, each target with its ``box`` in traces and seconds.

    Raises
    ------
    GPR3DError
        A file without that channel, or with boxes outside the record.
    """
    from gpr3d.io.detections import read_detections

    chans = read_detections(path)
    if not 0 <= channel < len(chans):
        raise GPR3DError(f"{path}: has {len(chans)} channel(s); no channel {channel}")
    return {"input": str(input_name if input_name is not None else path),
            "targets": targets_from_file(path, chans[channel]["targets"], survey)}
