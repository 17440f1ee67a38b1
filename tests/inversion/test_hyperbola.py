"""The classical hyperbola fit: exact travel paths, recovery of known parameters, honest uncertainties."""

import math

import numpy as np
import pytest

from gpr3d.core.units import C0
from gpr3d.inversion.hyperbola import (HyperbolaFit, _circle_path, combine_permittivity, fit_hyperbola,
                                       pick_arrivals)


def brute_path(x, h, x0, zc, r, n=400001):
    ang = np.linspace(0, 2 * np.pi, n)
    px, pz = x0 + r * np.cos(ang), zc + r * np.sin(ang)
    return np.min(np.hypot(px[None] - (x[:, None] - h / 2), pz[None]) + np.hypot(px[None] - (x[:, None] + h / 2),
                                                                                   pz[None]), axis=1)


@pytest.mark.parametrize("h, x0, zc, r", [(0.04, 0.02, 0.09, 0.01), (0.0, 0.0, 0.5, 0.3), (0.2, -0.1, 1.2, 0.6),
                                          (0.01, 0.3, 0.05, 0.04)])
def test_reflection_path_on_a_circle_is_the_shortest(h, x0, zc, r):
    x = np.linspace(-1.0, 1.0, 41)
    np.testing.assert_allclose(_circle_path(x, h, x0, zc, r), brute_path(x, h, x0, zc, r), atol=2e-9)


def _picks(x, *, t0, h, x0, zc, r, eps):
    v = C0 / math.sqrt(eps)
    return t0 + _circle_path(x, h, x0, zc, r) / v if r > 0 else \
        t0 + (np.hypot(x - h / 2 - x0, zc) + np.hypot(x + h / 2 - x0, zc)) / v


@pytest.mark.parametrize("model, r", [("point", 0.0), ("cylinder", 0.05), ("cylinder", 0.2)])
def test_exact_picks_give_the_parameters_back(model, r):
    x = np.linspace(0.0, 1.2, 121)
    t = _picks(x, t0=3e-9, h=0.06, x0=0.55, zc=0.35 + r, r=r, eps=9.0)
    f = fit_hyperbola(x, t, t0_s=3e-9, offset_m=0.06, frequency_hz=5e8, model=model, traces=np.arange(x.size))
    assert f.ok and f.model == model
    assert f.eps_r == pytest.approx(9.0, rel=1e-4)
    assert f.depth_m == pytest.approx(0.35, abs=1e-4)  # depth to the top
    assert f.x0_m == pytest.approx(0.55, abs=1e-5)
    assert f.radius_m == pytest.approx(r, abs=1e-3)
    assert f.apex_trace == pytest.approx(55.0, abs=1e-3)
    # the apex time is the arrival at x0
    assert f.apex_time_s == pytest.approx(float(_picks(np.array([0.55]), t0=3e-9, h=0.06, x0=0.55, zc=0.35 + r,
                                                       r=r, eps=9.0)[0]), abs=1e-13)


def test_the_point_model_underestimates_permittivity_over_a_wide_pipe_and_auto_takes_the_cylinder():
    x = np.linspace(-1.0, 1.0, 201)
    t = _picks(x, t0=0.0, h=0.0, x0=0.0, zc=0.8, r=0.3, eps=6.0)
    point = fit_hyperbola(x, t, t0_s=0.0, model="point")
    auto = fit_hyperbola(x, t, t0_s=0.0, model="auto")
    assert point.eps_r < 6.0 * 0.8  # eps_point ~ eps (zc - R) / zc
    assert auto.model == "cylinder" and auto.eps_r == pytest.approx(6.0, rel=1e-3)


def test_uncertainties_cover_the_errors_under_noise():
    rng = np.random.default_rng(1)
    x = np.linspace(0.0, 2.0, 101)
    truth = _picks(x, t0=2e-9, h=0.1, x0=1.1, zc=0.6, r=0.0, eps=12.0)
    z_eps, z_depth = [], []
    for _ in range(40):
        t = truth + rng.normal(0, 50e-12, x.size)
        f = fit_hyperbola(x, t, t0_s=2e-9, offset_m=0.1, frequency_hz=4e8, model="point")
        z_eps.append((f.eps_r - 12.0) / f.sigma_eps_r)
        z_depth.append((f.depth_m - 0.6) / f.sigma_depth_m)
    # standard errors from the Jacobian: the normalised errors scatter about one sigma
    assert 0.6 < np.std(z_eps) < 1.6 and 0.6 < np.std(z_depth) < 1.6
    assert abs(np.mean(z_eps)) < 0.6


def test_too_few_picks_are_refused_not_fitted():
    f = fit_hyperbola([0.1, 0.2, 0.3], [1e-9, 1.1e-9, 1.3e-9], t0_s=0.0)
    assert not f.ok and "usable picks" in f.reason
    assert f.to_dict()["eps_r"] is None  # NaN is written as null


def test_combine_permittivity_weights_and_drops_outliers():
    fits = [HyperbolaFit(ok=True, eps_r=6.0, sigma_eps_r=0.1), HyperbolaFit(ok=True, eps_r=6.2, sigma_eps_r=0.2),
            HyperbolaFit(ok=True, eps_r=14.0, sigma_eps_r=0.3), HyperbolaFit(ok=False)]
    eps, sig, n = combine_permittivity(fits)
    assert n == 2
    assert eps == pytest.approx((6.0 / 0.01 + 6.2 / 0.04) / (1 / 0.01 + 1 / 0.04))
    assert sig == pytest.approx(1 / math.sqrt(1 / 0.01 + 1 / 0.04))
    assert math.isnan(combine_permittivity([])[0])


def _pulses(times, tt, f, width_periods=0.6, amp=1.0):
    """A Gaussian-modulated cosine of frequency f centred at each time (rows: traces), amplitude ``amp`` per trace."""
    sig = width_periods / f
    amp = np.broadcast_to(np.asarray(amp, float), times.shape)[:, None]
    return amp * np.cos(2 * np.pi * f * (tt[None, :] - times[:, None])) \
        * np.exp(-0.5 * ((tt[None, :] - times[:, None]) / sig) ** 2)


def test_tracking_stays_on_its_own_hyperbola_where_another_crosses():
    dt, ns, f = 1e-11, 900, 2e9
    x = np.linspace(0, 0.6, 61)
    tt = np.arange(ns) * dt
    a = _picks(x, t0=1e-9, h=0.0, x0=0.25, zc=0.15, r=0.0, eps=4.0)
    b = _picks(x, t0=1e-9, h=0.0, x0=0.40, zc=0.20, r=0.0, eps=4.0)
    env = np.abs(__import__("scipy.signal").signal.hilbert(_pulses(a, tt, f) + 0.8 * _pulses(b, tt, f), axis=1))
    box = [5, a.min() - 0.5 / f, 45, ns * dt]
    tr, tp, amp = pick_arrivals(env, dt, box, apex_trace=25, apex_time_s=float(a.min()), period_s=1 / f)
    assert tr.size >= 30 and 25 in tr
    near = np.abs(tp - a[tr]) < 0.15 / f
    assert near.mean() > 0.9  # a few picks where the two pulses overlap may merge


def test_joint_fit_of_a_synthetic_record_recovers_speed_radii_and_depths():
    """Several cylinders in one record, direct wave included: one speed, each target's depth and radius back."""
    from gpr3d.core.survey import Survey
    from gpr3d.inversion.hyperbola import fit_record, time_zero

    f, dt, ns, h, eps = 1.0e9, 2e-11, 1500, 0.05, 7.0
    v = C0 / math.sqrt(eps)
    x = np.arange(240) * 0.01
    tt = np.arange(ns) * dt
    t_dw = 3e-9
    t0 = time_zero(t_dw, h, v)
    targets = [(0.5, 0.30, 0.02), (1.2, 0.45, 0.10), (1.9, 0.25, 0.05)]  # x0, top depth, radius
    data = 3 * _pulses(np.full(x.size, t_dw), tt, f)
    boxes, apexes = [], []
    for x0, top, r in targets:
        t = t0 + _circle_path(x, h, x0, top + r, r) / v
        obliquity = ((top + r) / np.hypot(x - x0, top + r)) ** 4  # a broadside antenna's pattern: tails fade
        data += _pulses(t, tt, f, amp=obliquity)
        sel = np.nonzero(np.abs(x - x0) <= top + r)[0]
        boxes.append([int(sel[0]), float(t.min() - 0.7 / f), int(sel[-1]), float(t[sel].max() + 0.7 / f)])
        apexes.append((float(np.interp(x0, x, np.arange(x.size))), float(t.min())))
    pos = np.stack([x, 0 * x, 0 * x], axis=1)
    s = Survey(data=data, dt_s=dt, positions_xyz=pos, offset_m=h, frequency_hz=f)
    fits, info = fit_record(s, boxes, apexes=apexes, model="cylinder")
    assert info["n_targets"] == 3
    assert info["eps_r"] == pytest.approx(eps, rel=0.02)
    assert info["t0_s"] == pytest.approx(t0, abs=0.03 / f)
    for (x0, top, r), fit in zip(targets, fits):
        assert fit.ok and fit.x0_m == pytest.approx(x0, abs=0.005)
        assert fit.depth_m == pytest.approx(top, abs=0.005)
        assert fit.radius_m == pytest.approx(r, abs=0.02)
