import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from gpr3d.core.raypath import S_AIR, air_ground_time, air_ground_times

C = 299792458.0


def _least_time(h, d, rho, eps_r):
    """Fermat by a bounded scalar minimisation over the crossing point (and both ends of the range)."""
    sg = math.sqrt(eps_r) / C

    def t(s):  # s: horizontal distance run in the air
        return math.hypot(h, s) / C + math.hypot(d, rho - s) * sg

    r = minimize_scalar(t, bounds=(0.0, rho), method="bounded", options={"xatol": 1e-14})
    return min(r.fun, t(0.0), t(rho))


def test_the_time_is_the_least_over_where_the_ray_crosses_the_surface():
    """Antennas 2 mm to 1 m up, points 3 mm to 5 m down and up to 10 m away, eps_r 1.05 to 81: within 0.5 ps of
    a bounded minimisation, from numba (float64 and float32 arguments) and from the array version."""
    rng = np.random.default_rng(4)
    n = 400
    h, d = 10 ** rng.uniform(-2.7, 0, n), 10 ** rng.uniform(-2.5, 0.7, n)
    rho, eps = 10 ** rng.uniform(-3, 1, n), rng.uniform(1.05, 81, n)
    want = np.array([_least_time(*a) for a in zip(h, d, rho, eps)])
    sg = np.sqrt(eps) / C
    got = np.array([air_ground_time(*a, S_AIR, b) for a, b in zip(zip(h, d, rho), sg)])
    np.testing.assert_allclose(got, want, rtol=0, atol=5e-13)
    np.testing.assert_allclose(air_ground_times(h, d, rho, S_AIR, sg), want, rtol=0, atol=5e-13)
    f = np.float32
    got32 = np.array([air_ground_time(f(a), f(b), f(c), f(S_AIR), f(s)) for a, b, c, s in zip(h, d, rho, sg)])
    np.testing.assert_allclose(got32, want, rtol=2e-6, atol=5e-13)


@pytest.mark.parametrize("fn", [air_ground_time, air_ground_times])
def test_the_limits_by_hand(fn):
    sg = 3.0 / C  # eps_r 9
    # straight down: the air leg then the ground leg
    assert float(fn(0.1, 0.3, 0.0, S_AIR, sg)) == pytest.approx(0.1 / C + 0.9 / C, rel=1e-12, abs=0)
    # no air: the straight ray through the ground from the antenna's height
    assert float(fn(0.0, 0.3, 0.4, S_AIR, sg)) == pytest.approx(0.5 * 3 / C, rel=1e-12, abs=0)
    assert float(fn(-0.1, 0.4, 0.3, S_AIR, sg)) == pytest.approx(math.hypot(0.3, 0.3) * 3 / C, rel=1e-12, abs=0)
    # a point on the surface: all in the air
    assert float(fn(0.3, 0.0, 0.4, S_AIR, sg)) == pytest.approx(0.5 / C, rel=1e-12, abs=0)
    # eps_r 1: no refraction, the straight line at c
    assert float(fn(0.1, 0.2, 0.4, S_AIR, S_AIR)) == pytest.approx(0.5 / C, rel=1e-9, abs=0)
    # Snell holds at the crossing: a slow ground bends the ray so that the air leg runs nearly all the way
    t = float(fn(0.5, 0.01, 2.0, S_AIR, 9.0 / C))
    assert 0 < t - math.hypot(0.5, 2.0) / C < 0.01 * 9 / C * 1.01
