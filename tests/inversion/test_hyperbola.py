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


def test_picks_follow_a_synthetic_hyperbola():
    """Envelope peaks of Gaussian pulses placed on a hyperbola come back at the pulse centres."""
    dt, ns = 1e-11, 800
    x = np.linspace(0, 0.6, 61)
    t_true = _picks(x, t0=1e-9, h=0.0, x0=0.3, zc=0.2, r=0.0, eps=4.0)
    tt = np.arange(ns) * dt
    env = np.exp(-0.5 * ((tt[None, :] - t_true[:, None]) / 1.5e-10) ** 2)
    tr, tp, amp, rise = pick_arrivals(env, dt, [0, 0.5e-9, 60, ns * dt])
    assert tr.size == 61
    np.testing.assert_allclose(tp, t_true, atol=0.05 * dt)
    np.testing.assert_allclose(rise, 1.5e-10 * math.sqrt(2 * math.log(10)), rtol=0.02)
