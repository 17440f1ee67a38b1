"""Named processing steps on a :class:`~gpr3d.core.survey.Survey`, with provenance.

Each step wraps one pure array function from the ``gpr3d.processing`` modules, fills in
defaults from the survey (sample interval, time zero, centre frequency), and
appends ``{"step", "args", "result"?}`` to the survey's history. The CLI's
``--steps`` and :meth:`~gpr3d.core.survey.Survey.apply` use the :data:`STEPS` table.
"""

from __future__ import annotations

import inspect
from typing import Callable

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.jsonutil import jsonable
from gpr3d.core.poses import slerp
from gpr3d.core.units import C0
from gpr3d.processing import gain, timezero
from gpr3d.processing.background import remove_background as _remove_background, remove_dc as _remove_dc
from gpr3d.processing.dewow import dewow as _dewow
from gpr3d.processing.envelope import envelope as _envelope
from gpr3d.processing.filters import bandpass as _bandpass
from gpr3d.processing.resample import resample_traces as _resample_traces

__all__ = ["STEPS", "run_step", "parse_step", "describe_steps", "check_step_args"]


def _need_frequency(s, what: str) -> float:
    if s.frequency_hz is None:
        raise InvalidDataError(f"{what}: the survey has no centre frequency; give it explicitly")
    return s.frequency_hz


def time_zero(s, *, method: str = "first_break", threshold: float = 0.1, search_s: float | None = None,
              per_trace: bool = False, shift: bool = True, offset_correction: bool = True):
    """Estimate time zero from the direct wave; with ``shift`` cut the samples before it (t0 becomes 0).

    ``method``: ``first_break`` (first sample above ``threshold`` x trace maximum) or
    ``peak`` (direct-wave peak within ``search_s``). ``per_trace`` aligns every trace
    on its own estimate (removes trigger jitter); otherwise the median is used. With
    ``offset_correction`` the direct air wave's travel time ``offset / c`` is taken
    off the estimate: the wave left the antenna that much earlier.
    """
    t0 = timezero.estimate_time_zero(s.data, s.dt_s, method=method, threshold=threshold,
                                     search_s=search_s, per_trace=per_trace)
    if offset_correction and s.offset_m > 0:
        t0 = np.maximum(np.asarray(t0) - s.offset_m / C0, 0.0)
        t0 = float(t0) if not per_trace else t0
    result = {"t0_s": (np.median(t0) if per_trace else t0)}
    if not shift:
        if per_trace:
            raise InvalidDataError("per_trace time zero needs shift=True (one t0 per survey otherwise)")
        return {"t0_s": float(t0)}, result
    data = timezero.shift_traces(s.data, np.asarray(t0) / s.dt_s)
    return {"data": data, "t0_s": 0.0}, result


def dewow(s, *, window_s: float | None = None):
    """Running-mean dewow; ``window_s`` defaults to one period of the centre frequency."""
    w = window_s if window_s is not None else 1.0 / _need_frequency(s, "dewow")
    return {"data": _dewow(s.data, s.dt_s, w)}, {"window_s": w}


def remove_dc(s, *, sample_range=None):
    """Subtract each trace's mean (optionally over ``sample_range = [start, stop]``)."""
    rng = None if sample_range is None else tuple(int(v) for v in sample_range)
    return {"data": _remove_dc(s.data, sample_range=rng)}, None


def remove_background(s, *, method: str = "mean", window_traces: int | None = None, trailing: bool = False):
    """Subtract the mean/median trace (whole survey, or a moving window of traces: centred, or ``trailing``)."""
    return {"data": _remove_background(s.data, method=method, window_traces=window_traces, trailing=trailing)}, None


def gain_tpow(s, *, power: float = 1.0, t_ref_s: float = 1e-9):
    """Multiply by ``((t - t0)/t_ref)^power``."""
    return {"data": gain.gain_tpow(s.data, s.dt_s, power=power, t0_s=s.t0_s, t_ref_s=t_ref_s)}, None


def gain_sec(s, *, alpha_per_s: float, power: float = 1.0, t_ref_s: float = 1e-9, max_gain: float | None = 1e6):
    """Spreading and exponential compensation."""
    data = gain.gain_sec(s.data, s.dt_s, alpha_per_s=alpha_per_s, power=power, t0_s=s.t0_s,
                         t_ref_s=t_ref_s, max_gain=max_gain)
    return {"data": data}, None


def gain_agc(s, *, window_s: float | None = None, eps: float = 1e-3):
    """AGC; ``window_s`` defaults to four periods of the centre frequency."""
    w = window_s if window_s is not None else 4.0 / _need_frequency(s, "gain_agc")
    return {"data": gain.gain_agc(s.data, s.dt_s, window_s=w, eps=eps)}, {"window_s": w}


def bandpass(s, *, fmin_hz: float | None = None, fmax_hz: float | None = None, order: int = 4):
    """Zero-phase Butterworth; without corners, 0.4x to 2x the centre frequency (below 0.9 Nyquist)."""
    if fmin_hz is None and fmax_hz is None:
        f = _need_frequency(s, "bandpass")
        fmin_hz, fmax_hz = 0.4 * f, min(2.0 * f, 0.45 / s.dt_s)
    data = _bandpass(s.data, s.dt_s, fmin_hz=fmin_hz, fmax_hz=fmax_hz, order=order)
    return {"data": data}, {"fmin_hz": fmin_hz, "fmax_hz": fmax_hz}


def envelope(s):
    """Hilbert envelope (instantaneous amplitude)."""
    return {"data": _envelope(s.data)}, None


def resample_spacing(s, *, spacing_m: float):
    """Traces at a constant spacing along the positions (stationary traces merged)."""
    if s.positions_xyz is None:
        raise InvalidDataError("resample_spacing needs trace positions (the survey has none)")
    data, _, src = _resample_traces(s.data, s.positions_xyz, spacing_m)
    base = np.arange(s.n_traces)
    changes = {"data": data}
    changes["positions_xyz"] = np.stack([np.interp(src, base, s.positions_xyz[:, k]) for k in range(3)], axis=1)
    if s.timestamps_s is not None:
        changes["timestamps_s"] = np.interp(src, base, s.timestamps_s)
    if s.orientations_quat_wxyz is not None:
        i0 = np.floor(src).astype(int)
        i1 = np.minimum(i0 + 1, s.n_traces - 1)
        q = s.orientations_quat_wxyz
        changes["orientations_quat_wxyz"] = slerp(q[i0], q[i1], src - i0)
    return changes, {"n_traces": int(data.shape[0])}


def topo_correct(s, *, eps_r: float | None = None, velocity_m_s: float | None = None):
    """Static (topographic) correction: each trace is delayed by the two-way time through the ground between the
    highest antenna position and its own, ``2 (z_max - z) / v``, so that equal times mean equal elevations; the
    record grows by the largest delay (zeros before). ``eps_r`` (default the survey's) or ``velocity_m_s``."""
    if s.positions_xyz is None:
        raise InvalidDataError("topo_correct needs trace positions with elevations (a track or GPS)")
    if velocity_m_s is None:
        eps = eps_r if eps_r is not None else s.eps_r
        if eps is None:
            raise InvalidDataError("topo_correct: give eps_r or velocity_m_s (the survey has no eps_r)")
        velocity_m_s = C0 / np.sqrt(eps)
    z = s.positions_xyz[:, 2]
    delay = 2.0 * (z.max() - z) / velocity_m_s
    shift = delay / s.dt_s
    n_extra = int(np.ceil(shift.max() - 1e-9))
    if n_extra > 20 * s.n_samples:
        raise InvalidDataError(f"topo_correct: {np.ptp(z):.1f} m of relief would lengthen the record "
                               f"{n_extra / s.n_samples:.0f}-fold: are the elevations in metres?")
    pad = np.zeros((s.n_traces, n_extra), np.float32)
    padded = np.concatenate([pad, np.asarray(s.data, np.float32), pad], axis=1)
    # a delay by shift = an advance of the front-padded trace by n_extra - shift; the highest trace keeps its times
    data = timezero.shift_traces(padded, n_extra - shift)[:, : s.n_samples + n_extra]
    return ({"data": data}, {"datum_elevation_m": float(z.max()), "max_delay_s": float(delay.max()),
                             "velocity_m_s": float(velocity_m_s)})


#: every step by name: what ``--steps`` and :meth:`~gpr3d.core.survey.Survey.apply` run
STEPS: dict[str, Callable] = {
    f.__name__: f
    for f in (time_zero, dewow, remove_dc, remove_background, gain_tpow, gain_sec, gain_agc,
              bandpass, envelope, resample_spacing, topo_correct)
}


def _record_s(s) -> float:
    return s.n_samples * s.dt_s


def _path_m(s) -> float:
    """Length of the survey's path (m; 0 without positions)."""
    if s.positions_xyz is None:
        return 0.0
    return float(np.hypot(*np.diff(s.positions_xyz[:, :2], axis=0).T).sum())


#: value checks per step argument, beyond its type: (test(value, survey), what it must be); each names the
#: argument in the error before any work starts
_RULES: dict[tuple[str, str], tuple[Callable, str]] = {
    ("time_zero", "threshold"): (lambda v, s: 0 < v <= 1, "in (0, 1]"),
    ("time_zero", "search_s"): (lambda v, s: 0 < v <= _record_s(s), "positive and at most the record's length"),
    ("time_zero", "method"): (lambda v, s: v in ("first_break", "peak"), "'first_break' or 'peak'"),
    ("dewow", "window_s"): (lambda v, s: 2 * s.dt_s <= v <= _record_s(s),
                            "between two samples and the record's length"),
    ("remove_background", "method"): (lambda v, s: v in ("mean", "median"), "'mean' or 'median'"),
    ("remove_background", "window_traces"): (lambda v, s: 2 <= v, "a whole number >= 2"),
    ("gain_tpow", "t_ref_s"): (lambda v, s: v > 0, "positive"),
    ("gain_sec", "t_ref_s"): (lambda v, s: v > 0, "positive"),
    ("gain_sec", "alpha_per_s"): (lambda v, s: v >= 0, ">= 0"),
    ("gain_sec", "max_gain"): (lambda v, s: v >= 1, ">= 1"),
    ("gain_agc", "window_s"): (lambda v, s: 2 * s.dt_s <= v <= _record_s(s),
                               "between two samples and the record's length"),
    ("gain_agc", "eps"): (lambda v, s: v > 0, "positive"),
    ("bandpass", "order"): (lambda v, s: 1 <= v <= 10, "a whole number from 1 to 10"),
    ("bandpass", "fmin_hz"): (lambda v, s: 0 < v < 0.5 / s.dt_s, "between 0 and the Nyquist frequency"),
    ("bandpass", "fmax_hz"): (lambda v, s: 0 < v < 0.5 / s.dt_s, "between 0 and the Nyquist frequency"),
    ("resample_spacing", "spacing_m"): (lambda v, s: v > 0 and _path_m(s) / v <= 20 * s.n_traces + 1,
                                        "positive and give at most 20 times the traces there are"),
    ("topo_correct", "eps_r"): (lambda v, s: v >= 1, ">= 1"),
    ("topo_correct", "velocity_m_s"): (lambda v, s: 1e6 <= v <= C0, "a wave speed in m/s, at most c"),
}

_BOOL_WORDS = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}


def _typed(step: str, name: str, value, annotation: str, survey):
    """``value`` as the type its parameter's annotation names (``bool``, ``int``, ``float``, ``str``, optional
    ``None``), checked by :data:`_RULES`; otherwise an :class:`~gpr3d.core.errors.InvalidDataError` naming the step and argument."""
    kinds = [k.strip() for k in str(annotation).split("|")]
    where = f"{step}: {name}"
    if value is None:
        if "None" in kinds:
            return None
        raise InvalidDataError(f"{where} must be given (not none)")
    if "bool" in kinds:
        if isinstance(value, bool):
            return value
        word = str(value).strip().lower()
        if word in _BOOL_WORDS:
            return _BOOL_WORDS[word]
        raise InvalidDataError(f"{where} must be true or false, got {value!r}")
    if "int" in kinds or "float" in kinds:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise InvalidDataError(f"{where} must be a finite number, got {value!r}")
        if "int" in kinds:
            if float(value) != int(value):
                raise InvalidDataError(f"{where} must be a whole number, got {value!r}")
            value = int(value)
        else:
            value = float(value)
    elif "str" in kinds and not isinstance(value, str):
        raise InvalidDataError(f"{where} must be a word, got {value!r}")
    rule = _RULES.get((step, name))
    if rule is not None and not rule[0](value, survey):
        raise InvalidDataError(f"{where} must be {rule[1]}, got {value!r}")
    return value


def _check_sample_range(value, survey):
    """``remove_dc``'s ``sample_range``: ``[start, stop]``, whole sample indices with 0 <= start < stop <= n."""
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) != 2 or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or float(v) != int(v) for v in value):
        raise InvalidDataError(f"remove_dc: sample_range must be two whole sample indices [start, stop], got {value!r}")
    a, b = int(value[0]), int(value[1])
    if not 0 <= a < b <= survey.n_samples:
        raise InvalidDataError(f"remove_dc: sample_range must satisfy 0 <= start < stop <= {survey.n_samples} "
                               f"(the samples per trace), got {value!r}")
    return [a, b]


def check_step_args(survey, step: str, kwargs: dict) -> dict:
    """``kwargs`` of ``step`` checked against its signature and rules (types, ranges, the survey's record), as the
    values the step will use; one :class:`~gpr3d.core.errors.InvalidDataError` naming the step and argument otherwise."""
    func = STEPS[step]
    sig = inspect.signature(func)
    try:
        sig.bind(survey, **kwargs)
    except TypeError as exc:
        raise InvalidDataError(f"{step}: {exc}") from None
    out = {}
    for name, value in kwargs.items():
        if (step, name) == ("remove_dc", "sample_range"):
            out[name] = _check_sample_range(value, survey)
        else:
            out[name] = _typed(step, name, value, sig.parameters[name].annotation, survey)
    if step == "bandpass" and out.get("fmin_hz") is not None and out.get("fmax_hz") is not None \
            and not out["fmin_hz"] < out["fmax_hz"]:
        raise InvalidDataError(f"bandpass: fmin_hz must be below fmax_hz, got {out['fmin_hz']} and {out['fmax_hz']}")
    return out


def run_step(survey, step: str, **kwargs):
    """Apply ``step`` to ``survey``; return a new Survey with the step in its history."""
    if step not in STEPS:
        raise InvalidDataError(f"unknown processing step {step!r}; known: {', '.join(STEPS)}")
    func = STEPS[step]
    kwargs = check_step_args(survey, step, kwargs)
    try:
        changes, result = func(survey, **kwargs)
    except ValueError as exc:  # bad parameter values from the array functions
        if isinstance(exc, InvalidDataError):
            raise
        raise InvalidDataError(f"{step}: {exc}") from None
    out = survey._derive(step, kwargs, **changes)
    if result:
        out.history[-1]["result"] = jsonable(result)
    return out


def _parse_value(text: str):
    import json

    low = text.lower()
    if low in ("none", "null"):
        return None
    if low in ("true", "false"):
        return low == "true"
    if text.startswith("[") and text.endswith("]"):  # [start, stop]
        return [_parse_value(t.strip()) for t in text[1:-1].split(",") if t.strip()]
    if "," in text:
        return [_parse_value(t) for t in text.split(",")]
    try:
        return json.loads(text)
    except ValueError:
        return text


def parse_step(spec: str) -> tuple[str, dict]:
    """Parse ``'name:key=value:key=value'`` (the CLI's step syntax) into ``(name, kwargs)``."""
    name, *pairs = spec.split(":")
    kwargs = {}
    for pair in pairs:
        if "=" not in pair:
            raise InvalidDataError(f"bad step argument {pair!r} in {spec!r}: expected key=value")
        k, v = pair.split("=", 1)
        if k.strip() in kwargs:  # (the last one once won silently)
            raise InvalidDataError(f"step argument {k.strip()!r} given twice in {spec!r}")
        kwargs[k.strip()] = _parse_value(v.strip())
    if name not in STEPS:
        raise InvalidDataError(f"unknown processing step {name!r}; known: {', '.join(STEPS)}")
    return name, kwargs


def describe_steps() -> str:
    """One line per step: name, arguments, first docstring line (for ``--help``)."""
    lines = []
    for name, f in STEPS.items():
        params = [p for p in inspect.signature(f).parameters.values() if p.name != "s"]
        args = ",".join(p.name for p in params)
        doc = (f.__doc__ or "").strip().splitlines()[0]
        lines.append(f"  {name}{'[:' + args + ']' if args else ''}  {doc}")
    return "\n".join(lines)
