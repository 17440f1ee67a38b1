"""Wave speed, permittivity and depth from a hyperbola: the classical least-squares fit.

A buried cylinder crossing the profile (a point target when its radius is 0),
centre ``(x0, zc)`` and radius ``R`` in a host of wave speed ``v``, seen by a
transmitter and receiver ``h`` apart on the surface with their midpoint at ``x``,
answers at::

    t(x) = t0 + min over P on the circle (|tx - P| + |P - rx|) / v,   tx = (x - h/2, 0), rx = (x + h/2, 0)

(for a point, ``(|tx - C| + |rx - C|) / v`` with ``C = (x0, zc)``; times from the first recorded sample; ``t0`` is time zero, when the wave leaves
the surface). So the fit needs, for each hyperbola:

* **time zero from the data**: the direct wave (air and ground coupling between the
  antennas) is the first strong event common to every trace; its envelope peaks
  between the air wave's ``h / c`` and the ground wave's ``h / v`` after the pulse,
  a share ``DIRECT_WAVE_MIX`` of the way (:func:`time_zero`), so ``t0`` is solved
  with ``v`` (:func:`direct_wave_time`).
* **arrivals**: in each trace of the detection box, the first envelope peak of the
  background-removed record that reaches half of that trace's strongest in the
  box (the hyperbola is the earliest event under the box top). :func:`pick_arrivals`.
* **positions** of the traces along the profile (m): from the file's positions or
  a trace spacing.

:func:`fit_hyperbola` solves for ``x0, zc, v`` (and ``R`` with ``model="cylinder"``)
by robust least squares (SciPy's ``least_squares``, Cauchy loss scaled to a
twentieth of a period: picks further off, mostly on a neighbour's crossing tail,
count little), with each estimate's standard error from the Jacobian:
``eps_r = (c / v)^2`` and depth to top ``zc - R``. ``model="auto"`` keeps the
cylinder only where it explains the picks clearly better than the point. A known
radius (``radius_m``) fixes ``R``: one hyperbola of limited aperture cannot tell
the radius from the speed, and a point fit reads a rod's eps_r low by about
``R / zc``.
:func:`fit_boxes` runs it for every detection of a record and
:func:`combine_permittivity` gives one eps_r per record from all its hyperbolas;
:func:`fit_record` fits them all at once with one speed (the better estimate where a
record holds several hyperbolas; ``benchmarks/eval_depth_fit.py`` compares them).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0, velocity_from_eps_r
from gpr3d.io.coco import BOX_PAD_PERIODS
from gpr3d.processing.analytic import analytic, running_mean

#: where the direct wave's envelope peaks between the air wave (0) and the ground wave (1), for antennas on the
#: ground: the median over 40 records of the gprMax training twin (0.616, spread 0.03 from 100 MHz to 1.7 GHz, eps_r
#: 4-24; ``python benchmarks/eval_time_zero.py``, ``benchmarks/results/time_zero.md``). Half-way (0.5) put time zero
#: about a tenth of the offset's ground-wave delay late.
DIRECT_WAVE_MIX = 0.62

__all__ = ["DIRECT_WAVE_MIX", "HyperbolaFit", "direct_wave_time", "time_zero", "pick_arrivals", "fit_hyperbola", "fit_boxes",
           "combine_permittivity", "fit_record", "trace_positions", "MODELS"]

MODELS = ("auto", "point", "cylinder")
EPS_RANGE = (1.0, 81.0)


@dataclass
class HyperbolaFit:
    """One hyperbola's fit. Times from the first recorded sample; lengths in m along the profile / below the surface.

    Attributes
    ----------
    ok : bool
        Whether the fit converged to a physical answer; ``reason`` says why not.
    reason : str
        Why the fit was refused ("" when ``ok``).
    model : str
        ``"point"`` or ``"cylinder"``: the scatterer fitted.
    x0_m, depth_m, radius_m : float
        The apex's place along the profile, the depth of the target's top, and the radius (0 for a point).
    v_m_s, eps_r : float
        The host's wave speed and the relative permittivity it gives (``(c / v) ** 2``).
    sigma_x0_m, sigma_depth_m, sigma_eps_r : float
        One-sigma uncertainties from the fit's covariance.
    t0_s : float
        The time zero used.
    apex_trace, apex_time_s : float
        The apex as a fractional trace index and its arrival time.
    rms_s : float
        RMS misfit of the picks kept.
    n_picks : int
        Picks kept after the robust loss.
    """

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
        x = x - running_mean(x, w, axis=1)
    return np.abs(analytic(x, axis=1))


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


def direct_wave_time(survey) -> tuple[float, float]:
    """Envelope peak of the direct wave (s from the first sample) and its spread over traces (s).

    The direct wave (air and ground coupling between the antennas) is the first strong
    event common to every trace: the first envelope peak of the mean trace reaching
    half its largest, parabola-refined. The spread is the median absolute deviation of
    the same peak picked trace by trace.
    """
    data = np.asarray(survey.data, np.float64)
    k, _ = _first_peak(np.abs(analytic(data.mean(axis=0))))
    env = np.abs(analytic(data[:: max(1, data.shape[0] // 64)], axis=1))
    per = np.array([_first_peak(e)[0] for e in env])
    return k * survey.dt_s, float(np.median(np.abs(per - k))) * survey.dt_s


def time_zero(direct_wave_s: float, offset_m: float, v_m_s: float, mix: float | None = None) -> float:
    """Time zero (when the pulse's peak leaves the surface) from the direct wave's envelope peak.

    The direct wave mixes the air wave (``offset / c``) and the ground wave
    (``offset / v``); its envelope peaks between them, a share ``mix`` (default
    ``DIRECT_WAVE_MIX``) of the way from the first to the second.
    """
    m = DIRECT_WAVE_MIX if mix is None else mix
    if not (isinstance(m, (int, float)) and 0.0 <= m <= 1.0):  # NaN fails the range
        raise InvalidDataError(f"the direct wave's mix must be a share from 0 to 1, got {mix!r}")
    return direct_wave_s - offset_m / C0 - m * offset_m * (1.0 / v_m_s - 1.0 / C0)


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


def pick_arrivals(envelope: np.ndarray, dt_s: float, box, *, apex_trace: float | None = None,
                  apex_time_s: float | None = None, period_s: float | None = None, min_rel: float = 0.15):
    """Arrivals of the hyperbola in ``box`` = [trace_start, t_start_s, trace_end, t_end_s], tracked from its apex.

    The apex: the envelope peak within half a period of (``apex_trace``, ``apex_time_s``)
    when given (the detector's apex), else the earliest strong first peak in the box.
    From there, trace by trace outwards, the envelope peak (parabola-refined) nearest
    the hyperbola's continuation (the last pick plus the last step's rise), within
    ``-0.25 .. +0.35`` periods of it, until the peak falls under ``min_rel`` of the
    apex's or leaves the box. ``period_s`` defaults to a tenth of the box height.
    Returns ``(trace indices, times s, amplitudes)`` in trace order.
    """
    n, ns = envelope.shape
    i0, ta, i1, tb = (float(v) for v in box)
    c0, c1 = int(max(math.floor(i0), 0)), int(min(math.ceil(i1), n - 1))
    r0, r1 = int(max(math.floor(ta / dt_s), 0)), int(min(math.ceil(tb / dt_s), ns - 1))
    empty = np.zeros(0, int), np.zeros(0), np.zeros(0)
    if c1 < c0 or r1 - r0 < 3:
        return empty
    period = period_s or 0.1 * (tb - ta)

    def peak_in(trace, lo_s, hi_s, near_s=None):
        """The envelope's local maximum in the window (the one nearest ``near_s``, else the largest)."""
        k0, k1 = max(int(math.floor(lo_s / dt_s)), r0), min(int(math.ceil(hi_s / dt_s)), r1)
        if k1 - k0 < 2:
            return None
        seg = envelope[trace, k0 - 1 : k1 + 2] if k0 >= 1 and k1 + 2 <= ns else envelope[trace, k0 : k1 + 1]
        off = k0 - 1 if k0 >= 1 and k1 + 2 <= ns else k0
        inner = np.nonzero((seg[1:-1] >= seg[:-2]) & (seg[1:-1] > seg[2:]))[0] + 1
        if inner.size == 0:
            return None
        if near_s is None:
            k = int(inner[np.argmax(seg[inner])])
        else:
            k = int(inner[np.argmin(np.abs((off + inner) * dt_s - near_s))])
        y = float(k)
        den = seg[k - 1] - 2 * seg[k] + seg[k + 1]
        if den < 0:
            y += 0.5 * (seg[k - 1] - seg[k + 1]) / den
        return (off + y) * dt_s, float(seg[k])

    start = None
    if apex_trace is not None and apex_time_s is not None:
        j = int(np.clip(round(apex_trace), c0, c1))
        p = peak_in(j, apex_time_s - 0.5 * period, apex_time_s + 0.5 * period)
        start = (j, p) if p else None
    if start is None:  # the earliest strong first peak in the box
        block = envelope[c0 : c1 + 1, r0 : r1 + 1]
        peak = block.max(axis=1)
        strong = np.nonzero(peak >= 0.5 * peak.max())[0] if peak.max() > 0 else np.zeros(0, int)
        if strong.size == 0:
            return empty
        firsts = [(_first_peak(block[j])[0], j) for j in strong]
        y, j = min(firsts)
        start = (c0 + j, ((r0 + y) * dt_s, float(block[j, int(round(y))])))
    j0, (t_a, amp0) = start
    picks = {j0: (t_a, amp0)}
    for step in (-1, 1):
        hist, j = [t_a], j0 + step
        while c0 <= j <= c1:
            # continue the hyperbola: the last step's slope carried on (it steepens slowly)
            pred = hist[-1] + (max(hist[-1] - hist[-2], 0.0) if len(hist) > 1 else 0.0)
            p = peak_in(j, pred - 0.25 * period, pred + 0.35 * period, near_s=pred)
            if p is None or p[1] < min_rel * amp0:
                break
            picks[j] = p
            hist.append(p[0])
            j += step
    order = sorted(picks)
    return (np.asarray(order, int), np.asarray([picks[j][0] for j in order]),
            np.asarray([picks[j][1] for j in order]))


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


def _travel(p, x, h, with_radius, radius=None):
    """Two-way time from the surface for parameters ``p = [x0, zc, v(, r)]``; ``radius`` fixes r (p holds 3)."""
    x0, zc, v = p[0], p[1], p[2]
    if radius is not None:
        return _circle_path(x, h, x0, zc, radius) / v
    if not with_radius:
        return (np.hypot(x - h / 2 - x0, zc) + np.hypot(x + h / 2 - x0, zc)) / v
    return _circle_path(x, h, x0, zc, p[3]) / v


def _robust_solve(fun, p0, lo, hi, **kw):
    """Least squares under the narrow Cauchy loss, started at ``p0`` and from a broad soft-L1 solve; the lower cost wins."""
    from scipy.optimize import least_squares  # (here: scipy.optimize is a quarter of a second to import)

    direct = least_squares(fun, p0, bounds=(lo, hi), loss="cauchy", f_scale=1.0, x_scale="jac", **kw)
    broad = least_squares(fun, p0, bounds=(lo, hi), loss="soft_l1", f_scale=5.0, x_scale="jac", **kw)
    refined = least_squares(fun, broad.x, bounds=(lo, hi), loss="cauchy", f_scale=1.0, x_scale="jac", **kw)
    return refined if refined.cost < direct.cost else direct


def _t0(p, t0, dw, h):
    """Time zero: fixed, or from the direct wave's peak with this parameter set's speed."""
    return t0 if dw is None else time_zero(dw, h, p[2])


def _solve(x, t, t0, dw, h, with_radius, scale, x_guess, t_apex, radius=None):
    v_lo, v_hi = velocity_from_eps_r(EPS_RANGE[1]), velocity_from_eps_r(EPS_RANGE[0])
    span = max(float(x.max() - x.min()), 1e-3)
    r_known = 0.0 if radius is None else radius
    best = None
    for eps_guess in (4.0, 9.0, 20.0):  # a few starts: the misfit is not convex in v
        v = velocity_from_eps_r(eps_guess)
        z = max(0.5 * v * max(t_apex - _t0([0, 0, v], t0, dw, h), 1e-12), 1e-3) + r_known
        p0 = [x_guess, z, v] + ([0.3 * z] if with_radius else [])
        # a known radius: the centre lies at least that deep (the top below the surface)
        lo = [x.min() - span, 1e-4 + r_known, v_lo] + ([0.0] if with_radius else [])
        hi = [x.max() + span, 50.0 + r_known, v_hi] + ([50.0] if with_radius else [])
        p0 = np.clip(p0, np.asarray(lo) + 1e-9, np.asarray(hi) - 1e-9)

        def res(p):
            return (_t0(p, t0, dw, h) + _travel(p, x, h, with_radius, radius) - t) / scale

        try:
            sol = _robust_solve(res, p0, lo, hi)
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


def fit_hyperbola(x_m, t_s, *, t0_s: float | None = None, direct_wave_s: float | None = None,
                  offset_m: float = 0.0, frequency_hz: float | None = None, model: str = "auto",
                  traces=None, radius_m: float | None = None) -> HyperbolaFit:
    """Fit the picks ``(x_m, t_s)`` of one hyperbola (see the module docstring).

    Time zero: ``t0_s`` when known, else from the direct wave's envelope peak ``direct_wave_s``
    (:func:`time_zero`, solved with the speed); one of them is needed.

    One hyperbola of limited aperture cannot tell the radius from the speed (a point fit reads a cylinder's
    hyperbola flatter, ``eps_r`` low by about ``radius / (depth + radius)``; the free cylinder trades radius for
    speed within picking error), so a known radius is what makes ``eps_r`` accurate for a single target.

    Parameters
    ----------
    x_m, t_s : array_like
        The picks: positions along the profile (m) and arrival times from the first sample (s); non-finite
        pairs are dropped.
    t0_s : float, optional
        Time zero, when known.
    direct_wave_s : float, optional
        The direct wave's envelope peak, when time zero is not known.
    offset_m : float
        Transmitter-receiver offset.
    frequency_hz : float, optional
        Sets the robust loss's scale (a quarter period; else a tenth of the picks' time spread).
    model : {"auto", "point", "cylinder"}
        The scatterer; ``auto`` fits both and keeps the better.
    traces : array_like, optional
        The picks' trace indices: they give ``apex_trace``.
    radius_m : float, optional
        The target's radius when known (a rebar's size from the drawings): the cylinder of that radius is fitted
        (``x0``, centre depth and speed free).

    Returns
    -------
    HyperbolaFit
        ``ok`` False, with its ``reason``, where the picks cannot be fitted (too few, no curvature, unphysical).

    Raises
    ------
    InvalidDataError
        An unknown model, both or neither of ``t0_s`` and ``direct_wave_s``, a bad radius, or a radius with the
        point model.
    """
    if model not in MODELS:
        raise InvalidDataError(f"unknown hyperbola model {model!r}; choose one of {', '.join(MODELS)}")
    if (t0_s is None) == (direct_wave_s is None):
        raise InvalidDataError("give either the time zero t0_s or the direct wave's peak direct_wave_s")
    radius_m = _check_radius(radius_m)
    if radius_m is not None and model == "point":
        raise InvalidDataError("a known radius_m makes the target a cylinder of that radius: "
                               "model must be 'auto' or 'cylinder', not 'point'")
    x = np.asarray(x_m, dtype=float)
    t = np.asarray(t_s, dtype=float)
    good = np.isfinite(x) & np.isfinite(t)
    x, t = x[good], t[good]
    tr = None if traces is None else np.asarray(traces, dtype=float)[good]
    if x.size < 5 or np.ptp(x) <= 0:
        return HyperbolaFit(ok=False, reason=f"{x.size} usable picks (5 spread along the profile needed)")
    scale = 0.05 / frequency_hz if frequency_hz else max(0.1 * float(np.ptp(t)), 1e-12)
    k = int(np.argmin(t))
    if radius_m is not None:
        return _fit_known_radius(x, t, tr, t0_s, direct_wave_s, offset_m, scale, k, radius_m)
    fits = {}
    for m in (("point", "cylinder") if model == "auto" else (model,)):
        sol = _solve(x, t, t0_s, direct_wave_s, offset_m, m == "cylinder", scale, float(x[k]), float(t[k]))
        if sol is not None:
            fits[m] = sol
    if not fits:
        return HyperbolaFit(ok=False, reason="the fit did not converge", n_picks=int(x.size))
    choice = "point" if "point" in fits else "cylinder"
    if "cylinder" in fits and "point" in fits:
        sig_c, _ = _sigmas(fits["cylinder"], scale)
        # the cylinder only where it fits clearly better and its radius is determined
        if fits["cylinder"].cost < 0.8 * fits["point"].cost and sig_c[3] < 0.5 * max(fits["cylinder"].x[3], 1e-9):
            choice = "cylinder"
    elif model == "cylinder":
        choice = "cylinder"
    return _result(fits[choice], x, t, tr, t0_s, direct_wave_s, offset_m, scale,
                   radius=None if choice == "cylinder" else 0.0)


def _result(sol, x, t, tr, t0_s, dw, h, scale, radius) -> HyperbolaFit:
    """The fit's estimates and uncertainties from the solution ``sol``: a free radius (``p[3]``) when
    ``radius`` is None, else a cylinder of that radius (0: a point)."""
    sig, cov = _sigmas(sol, scale)
    x0, zc, v = (float(a) for a in sol.x[:3])
    free = radius is None
    r = float(sol.x[3]) if free else float(radius)
    eps = (C0 / v) ** 2
    if free and cov is not None:
        s_depth = math.sqrt(max(cov[1, 1] + cov[3, 3] - 2 * cov[1, 3], 0.0))
    else:
        s_depth = float(sig[1])
    t0 = _t0(sol.x, t0_s, dw, h)
    fixed = None if free or r == 0.0 else r

    def travel(xx):
        return _travel(sol.x, xx, h, free, fixed)

    resid = t0 + travel(x) - t
    apex_trace = float(np.interp(x0, x, tr)) if tr is not None and np.all(np.diff(x) >= 0) else float("nan")
    return HyperbolaFit(ok=True, model="cylinder" if r > 0 or free else "point", x0_m=x0, depth_m=zc - r,
                        radius_m=r, v_m_s=v, eps_r=eps, sigma_x0_m=float(sig[0]), sigma_depth_m=s_depth,
                        sigma_eps_r=float(2 * eps * sig[2] / v), t0_s=t0, apex_trace=apex_trace,
                        apex_time_s=t0 + float(travel(np.array([x0]))[0]),
                        rms_s=float(np.sqrt(np.mean(resid**2))), n_picks=int(x.size))


def _check_radius(radius_m):
    """A known target radius: None, or a finite number of metres >= 0 (one line naming a wrong one)."""
    if radius_m is None:
        return None
    if isinstance(radius_m, bool) or not isinstance(radius_m, (int, float, np.floating, np.integer)):
        raise InvalidDataError(f"radius_m must be a number of metres >= 0, got {radius_m!r}")
    r = float(radius_m)
    if not (math.isfinite(r) and 0.0 <= r <= 50.0):
        raise InvalidDataError(f"radius_m must be a number of metres in 0..50, got {radius_m!r}")
    return r


def _fit_known_radius(x, t, tr, t0_s, dw, h, scale, k, radius) -> HyperbolaFit:
    """:func:`fit_hyperbola` for a cylinder of known ``radius``: x0, centre depth and speed free."""
    sol = _solve(x, t, t0_s, dw, h, False, scale, float(x[k]), float(t[k]), radius=radius)
    if sol is None:
        return HyperbolaFit(ok=False, reason="the fit did not converge", n_picks=int(x.size))
    return _result(sol, x, t, tr, t0_s, dw, h, scale, radius)


def _record_picks(survey, boxes, apexes, trace_spacing_m, t0_s, remove_background=True):
    """Positions, the direct wave's peak (None when ``t0_s`` is given) and the picks ``(traces, times)`` per box."""
    x = trace_positions(survey, trace_spacing_m)
    dw = direct_wave_time(survey)[0] if t0_s is None else None
    env = _record_envelope(survey, boxes, remove_background)
    period = 1.0 / survey.frequency_hz if survey.frequency_hz else None
    picks = []
    for k, b in enumerate(boxes):
        b = [float(v) for v in b]
        # starts tried in turn until one tracks 5 picks: the given apex, the box's centre under its top
        # (the label rule's apex: BOX_PAD_PERIODS periods below the top), the earliest strong peak in the box
        starts = [apexes[k]] if apexes is not None else []
        if period:
            starts.append((0.5 * (b[0] + b[2]), b[1] + BOX_PAD_PERIODS * period))
        starts.append((None, None))
        for a in starts:
            tr, tt, _ = pick_arrivals(env, survey.dt_s, b, apex_trace=a[0], apex_time_s=a[1], period_s=period)
            if tr.size >= 5:
                break
        picks.append((tr, tt))
    return x, dw, picks


def fit_boxes(survey, boxes, *, apexes=None, trace_spacing_m: float | None = None, t0_s: float | None = None,
              model: str = "auto", remove_background: bool = True, radius_m=None) -> list[HyperbolaFit]:
    """:func:`fit_hyperbola` for every box ``[trace_start, t_start_s, trace_end, t_end_s]`` of ``survey``.

    Before picking, the median of the traces outside every box (the direct wave and flat layers, no hyperbola) is
    removed, when at least a tenth of the traces (8 or more) lie outside the boxes.

    Parameters
    ----------
    survey : Survey
        The B-scan.
    boxes : list of sequence
        ``[trace_start, t_start_s, trace_end, t_end_s]`` per hyperbola (times from the first sample).
    apexes : list of (trace, time_s), optional
        Where the tracking starts in each box (the detector's apexes; default: found in the box).
    trace_spacing_m : float, optional
        The spacing of the traces, instead of the file's positions.
    t0_s : float, optional
        Time zero; default: from the direct wave.
    model : {"auto", "point", "cylinder"}
        As in :func:`fit_hyperbola` (``cylinder`` where a radius is known).
    remove_background : bool
        Remove the median of the traces outside the boxes before picking.
    radius_m : float or list, optional
        The targets' known radius (m), one for all or one per box (None where unknown).

    Returns
    -------
    list of HyperbolaFit
        One per box, in order.
    """
    radii = _radii(radius_m, len(boxes))
    x, dw, picks = _record_picks(survey, boxes, apexes, trace_spacing_m, t0_s, remove_background)
    return [fit_hyperbola(x[tr], tt, t0_s=t0_s, direct_wave_s=dw, offset_m=survey.offset_m,
                          frequency_hz=survey.frequency_hz, model=model if r is None else "cylinder", traces=tr,
                          radius_m=r) for (tr, tt), r in zip(picks, radii)]


def _radii(radius_m, n: int) -> list:
    """``radius_m`` (None, one number, or one per box) as a checked list of ``n``."""
    if radius_m is None or isinstance(radius_m, (int, float, np.floating, np.integer)):
        return [_check_radius(radius_m)] * n
    if not isinstance(radius_m, (list, tuple, np.ndarray)) or np.ndim(radius_m) != 1:
        raise InvalidDataError(f"radius_m must be a number of metres, or a list of one per box, got {radius_m!r}")
    radii = list(radius_m)
    if len(radii) != n:
        raise InvalidDataError(f"radius_m has {len(radii)} values for {n} boxes: give one, or one per box")
    return [_check_radius(r) for r in radii]


def fit_record(survey, boxes, *, apexes=None, trace_spacing_m: float | None = None, t0_s: float | None = None,
               model: str = "cylinder", min_picks: int = 5) -> tuple[list[HyperbolaFit], dict]:
    """All hyperbolas of a record fitted together: one wave speed (and time zero), each target its own
    ``x0``, centre depth and radius (``model="cylinder"``) or none (``"point"``).

    One host speed for all targets is what a homogeneous host gives, and it keeps the
    radius of each target apart from the speed, which a single hyperbola of limited
    aperture cannot. Picks as :func:`fit_boxes`. Returns the per-target fits (all
    sharing ``eps_r``) and ``{"eps_r", "sigma_eps_r", "n_targets", "t0_s", "rms_s"}``.
    """
    if model not in ("point", "cylinder"):
        raise InvalidDataError(f"joint fit model must be 'point' or 'cylinder', got {model!r}")
    x, dw, picks = _record_picks(survey, boxes, apexes, trace_spacing_m, t0_s)
    picks = [(tr, tt) if tr.size >= min_picks and np.ptp(x[tr]) > 0 else None for tr, tt in picks]
    used = [k for k, pk in enumerate(picks) if pk is not None]
    fail = HyperbolaFit(ok=False, reason=f"fewer than {min_picks} picks")
    if not used:
        return [fail for _ in boxes], {"eps_r": float("nan"), "sigma_eps_r": float("nan"), "n_targets": 0}
    h = survey.offset_m
    scale = 0.05 / survey.frequency_hz if survey.frequency_hz else 1e-10
    per = 3 if model == "cylinder" else 2
    xs = [x[picks[k][0]] for k in used]
    ts = [picks[k][1] for k in used]
    v_lo, v_hi = velocity_from_eps_r(EPS_RANGE[1]), velocity_from_eps_r(EPS_RANGE[0])

    def unpack(p):
        return p[0], [p[1 + per * i : 1 + per * (i + 1)] for i in range(len(used))]

    def residuals(p):
        v, tg = unpack(p)
        t0 = t0_s if dw is None else time_zero(dw, h, v)
        out = []
        for xi, ti, q in zip(xs, ts, tg):
            path = _circle_path(xi, h, q[0], q[1], q[2]) if model == "cylinder" else \
                np.hypot(xi - h / 2 - q[0], q[1]) + np.hypot(xi + h / 2 - q[0], q[1])
            out.append((t0 + path / v - ti) / scale)
        return np.concatenate(out)

    # sparsity: each target's residuals depend on v and its own parameters
    n_res = sum(len(t) for t in ts)
    sparsity = np.zeros((n_res, 1 + per * len(used)), dtype=np.int8)
    sparsity[:, 0] = 1
    row = 0
    for i, t in enumerate(ts):
        sparsity[row : row + len(t), 1 + per * i : 1 + per * (i + 1)] = 1
        row += len(t)
    # starts: each target fitted alone (point model), with their median speed and with a few fixed speeds
    singles = [fit_hyperbola(xi, ti, t0_s=t0_s, direct_wave_s=dw, offset_m=h, frequency_hz=survey.frequency_hz,
                             model="point") for xi, ti in zip(xs, ts)]
    v_single = [f.v_m_s for f in singles if f.ok]
    starts = ([float(np.median(v_single))] if v_single else []) + [velocity_from_eps_r(e) for e in (4.0, 9.0, 20.0)]
    best = None
    for v in starts:
        t0g = t0_s if dw is None else time_zero(dw, h, v)
        p0, lo, hi = [v], [v_lo], [v_hi]
        for xi, ti, sf in zip(xs, ts, singles):
            k = int(np.argmin(ti))
            z = max(0.5 * v * max(ti[k] - t0g, 1e-12), 1e-3)
            x0g = sf.x0_m if sf.ok else float(xi[k])
            span = max(float(np.ptp(xi)), 1e-3)
            p0 += [x0g, z] + ([0.2 * z] if model == "cylinder" else [])
            lo += [float(xi.min()) - span, 1e-4] + ([0.0] if model == "cylinder" else [])
            hi += [float(xi.max()) + span, 50.0] + ([50.0] if model == "cylinder" else [])
        p0 = np.clip(p0, np.asarray(lo) + 1e-9, np.asarray(hi) - 1e-9)
        try:
            sol = _robust_solve(residuals, p0, lo, hi, jac_sparsity=sparsity, max_nfev=200 * len(p0))
        except ValueError:
            continue
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        return [HyperbolaFit(ok=False, reason="the joint fit did not converge") for _ in boxes], \
            {"eps_r": float("nan"), "sigma_eps_r": float("nan"), "n_targets": 0}
    jac = best.jac.toarray() if hasattr(best.jac, "toarray") else best.jac
    r = best.fun * scale
    s2 = float(np.sum(r**2) / max(r.size - best.x.size, 1))
    j = jac * scale
    try:
        cov = np.linalg.pinv(j.T @ j) * s2
    except np.linalg.LinAlgError:
        cov = np.full((best.x.size, best.x.size), np.inf)
    v, tg = unpack(best.x)
    eps = (C0 / v) ** 2
    s_eps = 2 * eps * math.sqrt(max(cov[0, 0], 0.0)) / v
    t0 = t0_s if dw is None else time_zero(dw, h, v)
    fits = [fail] * len(boxes)
    res_all = residuals(best.x) * scale
    ends = np.cumsum([0] + [len(t) for t in ts])
    for i, k in enumerate(used):
        q = tg[i]
        rr = float(q[2]) if model == "cylinder" else 0.0
        b = 1 + per * i
        if model == "cylinder":
            s_depth = math.sqrt(max(cov[b + 1, b + 1] + cov[b + 2, b + 2] - 2 * cov[b + 1, b + 2], 0.0))
        else:
            s_depth = math.sqrt(max(cov[b + 1, b + 1], 0.0))
        tr, tt = picks[k]
        pth = _circle_path(np.array([q[0]]), h, q[0], q[1], rr) if model == "cylinder" else \
            np.array([np.hypot(h / 2, q[1]) * 2])
        res_i = res_all[ends[i] : ends[i + 1]]
        fits[k] = HyperbolaFit(ok=True, model=model, x0_m=float(q[0]), depth_m=float(q[1]) - rr, radius_m=rr,
                               v_m_s=v, eps_r=eps, sigma_x0_m=math.sqrt(max(cov[b, b], 0.0)), sigma_depth_m=s_depth,
                               sigma_eps_r=s_eps, t0_s=t0, apex_trace=float(np.interp(q[0], x[tr], tr)),
                               apex_time_s=t0 + float(pth[0]) / v, rms_s=float(np.sqrt(np.mean(res_i**2))),
                               n_picks=int(tr.size))
    return fits, {"eps_r": eps, "sigma_eps_r": s_eps, "n_targets": len(used), "t0_s": t0,
                  "rms_s": float(np.sqrt(np.mean(r**2)))}


def _record_envelope(survey, boxes, remove_background: bool = True) -> np.ndarray:
    """Envelope for picking: the median of the traces outside every box removed (when enough lie outside)."""
    data = np.asarray(survey.data, dtype=np.float64)
    if remove_background:  # the direct wave and flat layers: the median of the traces outside every box
        outside = np.ones(survey.n_traces, bool)
        for b in boxes:
            outside[int(max(math.floor(b[0]), 0)) : int(math.ceil(b[2])) + 1] = False
        if outside.sum() >= max(8, survey.n_traces // 10):
            data = data - np.median(data[outside], axis=0, keepdims=True)
    return _envelope(data, survey.dt_s, survey.frequency_hz)


def combine_permittivity(fits) -> tuple[float, float, int]:
    """One eps_r for a record from its hyperbolas: the inverse-variance weighted mean of the fits that converged with
    a finite, positive uncertainty, after dropping those more than 3 sigma from the weighted median (a hyperbola
    distorted by a neighbour).

    Parameters
    ----------
    fits : iterable of HyperbolaFit
        The record's fits.

    Returns
    -------
    tuple of (float, float, int)
        ``(eps_r, sigma, number of fits used)``; ``(nan, nan, 0)`` when none can be used.
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
