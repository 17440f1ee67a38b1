"""Wave speed, permittivity and depth from a hyperbola: the classical least-squares fit.

A buried cylinder crossing the profile (a point target when its radius is 0),
centre ``(x0, zc)`` and radius ``R`` in a host of wave speed ``v``, seen by a
transmitter and receiver ``h`` apart on the surface with their midpoint at ``x``,
answers at::

    t(x) = t0 + min over P on the circle (|tx - P| + |P - rx|) / v,   tx = (x - h/2, 0), rx = (x + h/2, 0)

(for a point, ``(|tx - C| + |rx - C|) / v`` with ``C = (x0, zc)``; times from the first recorded sample; ``t0`` is time zero, when the wave leaves
the surface). So the fit needs, for each hyperbola:

* **time zero from the data**: the direct wave (air and ground coupling between the
  antennas) is the first strong event common to every trace; its envelope starts
  to rise ``h / c`` after the pulse's onset leaves (the air wave comes first).
  Arrivals are picked at envelope peaks, so the pulse's rise time (onset to peak,
  measured on the hyperbola's own strongest traces) is added.
  :func:`time_zero_from_direct_wave`.
* **arrivals**: in each trace of the detection box, the first envelope peak of the
  background-removed record that reaches half of that trace's strongest in the
  box (the hyperbola is the earliest event under the box top). :func:`pick_arrivals`.
* **positions** of the traces along the profile (m): from the file's positions or
  a trace spacing.

:func:`fit_hyperbola` solves for ``x0, zc, v`` (and ``R`` with ``model="cylinder"``)
by robust least squares (SciPy's ``least_squares``, soft-L1 loss scaled to a
quarter period), with each estimate's standard error from the Jacobian:
``eps_r = (c / v)^2`` and depth to top ``zc - R``. ``model="auto"`` keeps the
cylinder only where it explains the picks clearly better than the point.
:func:`fit_boxes` runs it for every detection of a record and
:func:`combine_permittivity` gives one eps_r per record from all its hyperbolas.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.optimize import least_squares
from scipy.signal import hilbert

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0

__all__ = ["HyperbolaFit", "time_zero_from_direct_wave", "pick_arrivals", "fit_hyperbola", "fit_boxes",
           "combine_permittivity", "trace_positions", "MODELS"]

MODELS = ("auto", "point", "cylinder")
EPS_RANGE = (1.0, 81.0)


@dataclass
class HyperbolaFit:
    """One hyperbola's fit. Times from the first recorded sample; lengths in m along the profile / below the surface."""

    ok: bool
    reason: str = ""
    model: str = "point"
    x0_m: float = float("nan")
    depth_m: float = float("nan")  #: depth of the top below the surface
    radius_m: float = 0.0
    v_m_s: float = float("nan")
    eps_r: float = float("nan")
    sigma_x0_m: float = float("nan")
    sigma_depth_m: float = float("nan")
    sigma_eps_r: float = float("nan")
    t0_s: float = float("nan")  #: time zero used
    apex_trace: float = float("nan")  #: fractional trace index at x0
    apex_time_s: float = float("nan")  #: arrival time at x0 (from the first sample)
    rms_s: float = float("nan")  #: RMS misfit of the picks kept
    n_picks: int = 0

    def to_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


def _envelope(data: np.ndarray, dt_s: float, frequency_hz: float | None) -> np.ndarray:
    """Envelope of the dewowed traces (a running mean over ~1 period removed)."""
    x = np.asarray(data, dtype=np.float64)
    if frequency_hz:
        w = int(np.clip(round(1.0 / (frequency_hz * dt_s)), 3, max(3, x.shape[1] // 2)))
        x = x - uniform_filter1d(x, w, axis=1, mode="nearest")
    return np.abs(hilbert(x, axis=1))


def _first_peak(e: np.ndarray, level: float = 0.5) -> tuple[float, float]:
    """First local maximum of ``e`` reaching ``level`` of its largest (parabola-refined index) and its value."""
    k = int(np.argmax(e >= level * e.max()))
    while k + 1 < e.size and e[k + 1] >= e[k]:
        k += 1
    y, v = float(k), float(e[k])
    if 0 < k < e.size - 1:
        den = e[k - 1] - 2 * e[k] + e[k + 1]
        if den < 0:
            y += 0.5 * (e[k - 1] - e[k + 1]) / den
    return y, v


def _onset(e: np.ndarray, k: float, frac: float) -> float:
    """Where the envelope ``e`` last rises through ``frac`` of its value at peak index ``k`` (fractional index)."""
    j = int(round(k))
    lev = frac * e[j]
    while j > 0 and e[j - 1] >= lev:
        j -= 1
    if j == 0:
        return 0.0
    a, b = e[j - 1], e[j]
    return j - 1 + (lev - a) / (b - a) if b > a else float(j)


ONSET_FRACTION = 0.1


def time_zero_from_direct_wave(survey, *, offset_m: float | None = None) -> tuple[float, float]:
    """When the pulse's onset leaves the surface (s from the first sample), and the spread over traces.

    The direct wave (the air wave between the antennas, then the ground wave) is the
    first strong event common to every trace. Its envelope (mean trace) first rises
    through a tenth of its first strong peak when the air wave arrives, ``offset / c``
    after the pulse's onset left. The spread is the median absolute deviation of the
    same onset picked trace by trace (s). Arrivals picked at their envelope peak add
    the pulse's rise time (:func:`fit_boxes` measures it on each hyperbola).
    """
    h = survey.offset_m if offset_m is None else float(offset_m)
    data = np.asarray(survey.data, np.float64)
    mean_env = np.abs(hilbert(data.mean(axis=0)))
    k, _ = _first_peak(mean_env)
    on = _onset(mean_env, k, ONSET_FRACTION)
    env = np.abs(hilbert(data[:: max(1, data.shape[0] // 64)], axis=1))
    per = []
    for e in env:
        kk, _ = _first_peak(e)
        per.append(_onset(e, kk, ONSET_FRACTION))
    spread = float(np.median(np.abs(np.asarray(per) - on))) * survey.dt_s
    return on * survey.dt_s - h / C0, spread


def trace_positions(survey, trace_spacing_m: float | None = None) -> np.ndarray:
    """Position of every trace along the profile (m): cumulative distance of the file's positions, or ``i * spacing``."""
    if trace_spacing_m is not None:
        if not (math.isfinite(trace_spacing_m) and trace_spacing_m > 0):
            raise InvalidDataError(f"trace spacing must be a positive number of metres, got {trace_spacing_m!r}")
        return np.arange(survey.n_traces) * float(trace_spacing_m)
    d = survey.distances_m
    if d is None or not np.all(np.isfinite(d)) or d[-1] - d[0] <= 0:
        raise InvalidDataError("the record has no trace positions: give a trace spacing (m)")
    return np.asarray(d, dtype=float)


def pick_arrivals(envelope: np.ndarray, dt_s: float, box, *, level: float = 0.5, min_rel: float = 0.15):
    """Arrival per trace of ``box`` = [trace_start, t_start_s, trace_end, t_end_s] in an envelope ``(traces, samples)``.

    In each trace, the first local maximum (parabola-refined) reaching ``level`` of
    that trace's largest value within the box's rows. Traces whose largest value is
    under ``min_rel`` of the box's strongest trace are skipped (the tails fade into
    noise). Returns ``(trace indices, times s, amplitudes, rise times s)``; the rise
    time is from the envelope's onset (a tenth of the peak) to its peak.
    """
    n, ns = envelope.shape
    i0, ta, i1, tb = box
    c0, c1 = int(max(math.floor(i0), 0)), int(min(math.ceil(i1), n - 1))
    r0, r1 = int(max(math.floor(ta / dt_s), 0)), int(min(math.ceil(tb / dt_s), ns - 1))
    empty = np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros(0)
    if c1 < c0 or r1 - r0 < 3:
        return empty
    block = envelope[c0 : c1 + 1, r0 : r1 + 1]
    peak = block.max(axis=1)
    strongest = float(peak.max()) if peak.size else 0.0
    tr, tt, aa, rise = [], [], [], []
    for j, e in enumerate(block):
        if strongest <= 0 or peak[j] < min_rel * strongest:
            continue
        y, v = _first_peak(e, level)
        full = envelope[c0 + j]
        rise.append((r0 + y - _onset(full, r0 + y, ONSET_FRACTION)) * dt_s)
        tr.append(c0 + j)
        tt.append((r0 + y) * dt_s)
        aa.append(v)
    if not tr:
        return empty
    return np.asarray(tr, int), np.asarray(tt), np.asarray(aa), np.asarray(rise)


def _circle_path(x, h, x0, zc, r):
    """Shortest path tx -> circle (centre (x0, depth zc), radius r) -> rx for antennas at x -+ h/2 on the surface.

    Newton's method on the angle of the reflection point, from the direction of the
    antenna midpoint (exact to float precision in a few steps; smooth in the parameters).
    """
    tx, rx = x - h / 2, x + h / 2
    th = np.arctan2(-zc, x - x0)  # angle (from the centre; depth positive down) pointing at the midpoint
    # P(th) = (x0 + r cos th, zc + r sin th) in (x, depth); the surface is depth 0
    for _ in range(4):
        c, s_ = np.cos(th), np.sin(th)
        px, pz = x0 + r * c, zc + r * s_
        dxt, dzt, dxr, dzr = px - tx, pz, px - rx, pz
        dt_, dr_ = np.hypot(dxt, dzt), np.hypot(dxr, dzr)
        dpx, dpz = -r * s_, r * c  # dP/dth
        g = (dxt * dpx + dzt * dpz) / dt_ + (dxr * dpx + dzr * dpz) / dr_
        # second derivative: |dP|^2/d - (d.dP)^2/d^3 + d.d2P/d, with d2P = -(P - C)
        d2px, d2pz = -r * c, -r * s_
        hh = (r * r / dt_ - (dxt * dpx + dzt * dpz) ** 2 / dt_**3 + (dxt * d2px + dzt * d2pz) / dt_
              + r * r / dr_ - (dxr * dpx + dzr * dpz) ** 2 / dr_**3 + (dxr * d2px + dzr * d2pz) / dr_)
        th = th - np.where(hh > 0, g / np.where(hh > 0, hh, 1.0), 0.0)
    c, s_ = np.cos(th), np.sin(th)
    px, pz = x0 + r * c, zc + r * s_
    return np.hypot(px - tx, pz) + np.hypot(px - rx, pz)


def _travel(p, x, h, with_radius):
    x0, zc, v = p[0], p[1], p[2]
    if not with_radius:
        return (np.hypot(x - h / 2 - x0, zc) + np.hypot(x + h / 2 - x0, zc)) / v
    return _circle_path(x, h, x0, zc, p[3]) / v


def _solve(x, t, t0, h, with_radius, scale, x_guess, t_apex):
    v_lo, v_hi = C0 / math.sqrt(EPS_RANGE[1]), C0 / math.sqrt(EPS_RANGE[0])
    span = max(float(x.max() - x.min()), 1e-3)
    best = None
    for eps_guess in (4.0, 9.0, 20.0):  # a few starts: the misfit is not convex in v
        v = C0 / math.sqrt(eps_guess)
        z = max(0.5 * v * max(t_apex - t0, 1e-12), 1e-3)
        p0 = [x_guess, z, v] + ([0.3 * z] if with_radius else [])
        lo = [x.min() - span, 1e-4, v_lo] + ([0.0] if with_radius else [])
        hi = [x.max() + span, 50.0, v_hi] + ([50.0] if with_radius else [])
        p0 = np.clip(p0, np.asarray(lo) + 1e-9, np.asarray(hi) - 1e-9)

        def res(p):
            return (t0 + _travel(p, x, h, with_radius) - t) / scale

        try:
            sol = least_squares(res, p0, bounds=(lo, hi), loss="soft_l1", f_scale=1.0, x_scale="jac")
        except ValueError:
            continue
        if with_radius and sol.x[3] > sol.x[1]:  # the top would lie above the surface
            continue
        if best is None or sol.cost < best.cost:
            best = sol
    return best


def _sigmas(sol, scale):
    """Standard errors of the parameters (robust residual scale)."""
    r = sol.fun * scale
    dof = max(r.size - sol.x.size, 1)
    s2 = float(np.sum(r**2) / dof)
    j = sol.jac * scale  # d(residual seconds)/d(parameter)
    try:
        cov = np.linalg.inv(j.T @ j) * s2
        return np.sqrt(np.clip(np.diag(cov), 0, None)), cov
    except np.linalg.LinAlgError:
        return np.full(sol.x.size, np.inf), None


def fit_hyperbola(x_m, t_s, *, t0_s: float, offset_m: float = 0.0, frequency_hz: float | None = None,
                  model: str = "auto", traces=None) -> HyperbolaFit:
    """Fit the picks ``(x_m, t_s)`` of one hyperbola (see the module docstring).

    ``frequency_hz`` sets the robust loss's scale (a quarter period; else a tenth of
    the picks' time spread). ``traces`` (the picks' trace indices) give ``apex_trace``.
    """
    if model not in MODELS:
        raise InvalidDataError(f"unknown hyperbola model {model!r}; choose one of {', '.join(MODELS)}")
    x = np.asarray(x_m, dtype=float)
    t = np.asarray(t_s, dtype=float)
    good = np.isfinite(x) & np.isfinite(t)
    x, t = x[good], t[good]
    tr = None if traces is None else np.asarray(traces, dtype=float)[good]
    if x.size < 5 or np.ptp(x) <= 0:
        return HyperbolaFit(ok=False, reason=f"{x.size} usable picks (5 spread along the profile needed)", t0_s=t0_s)
    scale = 0.25 / frequency_hz if frequency_hz else max(0.1 * float(np.ptp(t)), 1e-12)
    k = int(np.argmin(t))
    fits = {}
    for m in (("point", "cylinder") if model == "auto" else (model,)):
        sol = _solve(x, t, t0_s, offset_m, m == "cylinder", scale, float(x[k]), float(t[k]))
        if sol is not None:
            fits[m] = sol
    if not fits:
        return HyperbolaFit(ok=False, reason="the fit did not converge", t0_s=t0_s, n_picks=int(x.size))
    choice = "point" if "point" in fits else "cylinder"
    if "cylinder" in fits and "point" in fits:
        sig_c, _ = _sigmas(fits["cylinder"], scale)
        # the cylinder only where it fits clearly better and its radius is determined
        if fits["cylinder"].cost < 0.8 * fits["point"].cost and sig_c[3] < 0.5 * max(fits["cylinder"].x[3], 1e-9):
            choice = "cylinder"
    elif model == "cylinder":
        choice = "cylinder"
    sol = fits[choice]
    sig, cov = _sigmas(sol, scale)
    x0, zc, v = (float(a) for a in sol.x[:3])
    r = float(sol.x[3]) if choice == "cylinder" else 0.0
    eps = (C0 / v) ** 2
    s_eps = 2 * eps * sig[2] / v
    if choice == "cylinder" and cov is not None:
        s_depth = math.sqrt(max(cov[1, 1] + cov[3, 3] - 2 * cov[1, 3], 0.0))
    else:
        s_depth = float(sig[1])
    resid = (t0_s + _travel(sol.x, x, offset_m, choice == "cylinder") - t)
    apex_trace = float(np.interp(x0, x, tr)) if tr is not None and np.all(np.diff(x) >= 0) else float("nan")
    apex_time = t0_s + float(_travel(sol.x, np.array([x0]), offset_m, choice == "cylinder")[0])
    return HyperbolaFit(ok=True, model=choice, x0_m=x0, depth_m=zc - r, radius_m=r, v_m_s=v, eps_r=eps,
                        sigma_x0_m=float(sig[0]), sigma_depth_m=s_depth, sigma_eps_r=float(s_eps), t0_s=t0_s,
                        apex_trace=apex_trace, apex_time_s=apex_time,
                        rms_s=float(np.sqrt(np.mean(resid**2))), n_picks=int(x.size))


def fit_boxes(survey, boxes, *, trace_spacing_m: float | None = None, t0_s: float | None = None,
              model: str = "auto", remove_background: bool = True) -> list[HyperbolaFit]:
    """:func:`fit_hyperbola` for every box ``[trace_start, t_start_s, trace_end, t_end_s]`` of ``survey``.

    Time zero comes from the direct wave unless ``t0_s`` is given; positions from the
    file unless ``trace_spacing_m`` is given. Before picking, the median of the traces
    outside every box (the direct wave and flat layers, no hyperbola) is removed,
    when at least a tenth of the traces (8 or more) lie outside the boxes.
    """
    x = trace_positions(survey, trace_spacing_m)
    onset = time_zero_from_direct_wave(survey)[0] if t0_s is None else None
    data = np.asarray(survey.data, dtype=np.float64)
    if remove_background:  # the direct wave and flat layers: the median of the traces outside every box
        outside = np.ones(survey.n_traces, bool)
        for b in boxes:
            outside[int(max(math.floor(b[0]), 0)) : int(math.ceil(b[2])) + 1] = False
        if outside.sum() >= max(8, survey.n_traces // 10):
            data = data - np.median(data[outside], axis=0, keepdims=True)
    env = _envelope(data, survey.dt_s, survey.frequency_hz)
    out = []
    for b in boxes:
        b = [float(v) for v in b]
        # from the box top down; the hyperbola's first lobe lies at its top
        tr, tt, amp, rise = pick_arrivals(env, survey.dt_s, b)
        t0 = t0_s
        if t0 is None:  # peaks are picked: time zero of the peak = onset + the pulse's rise on its strongest traces
            strong = amp >= np.median(amp) if amp.size else amp.astype(bool)
            t0 = onset + (float(np.median(rise[strong])) if strong.any() else 0.0)
        out.append(fit_hyperbola(x[tr], tt, t0_s=t0, offset_m=survey.offset_m, frequency_hz=survey.frequency_hz,
                                 model=model, traces=tr))
    return out


def combine_permittivity(fits) -> tuple[float, float, int]:
    """One eps_r for a record from its hyperbolas: ``(eps_r, sigma, n used)``.

    The inverse-variance weighted mean of the fits that converged with a finite,
    positive uncertainty, after dropping those more than 3 sigma from the weighted
    median (a hyperbola distorted by a neighbour); ``(nan, nan, 0)`` when none.
    """
    e = np.array([f.eps_r for f in fits if f.ok and math.isfinite(f.sigma_eps_r) and f.sigma_eps_r > 0])
    s = np.array([f.sigma_eps_r for f in fits if f.ok and math.isfinite(f.sigma_eps_r) and f.sigma_eps_r > 0])
    if e.size == 0:
        return float("nan"), float("nan"), 0
    w = 1 / s**2
    order = np.argsort(e)
    cw = np.cumsum(w[order])
    med = float(e[order][np.searchsorted(cw, 0.5 * cw[-1])])
    keep = np.abs(e - med) <= 3 * np.hypot(s, 0.02 * med)
    e, w = e[keep], w[keep]
    mean = float(np.sum(w * e) / np.sum(w))
    return mean, float(1 / math.sqrt(np.sum(w))), int(e.size)
