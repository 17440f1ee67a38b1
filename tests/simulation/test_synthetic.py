import numpy as np
import pytest

from gpr3d.core.units import velocity_from_eps_r
from gpr3d.simulation.synthetic import point_targets_bscan, ricker


def test_ricker_peak_and_zero_crossings():
    f = 1e9
    assert ricker(0.0, f) == pytest.approx(1.0)
    # zeros of (1 - 2 pi^2 f^2 t^2) at t = 1 / (sqrt(2) pi f)
    assert ricker(1 / (np.sqrt(2) * np.pi * f), f) == pytest.approx(0.0, abs=1e-12)


def test_hyperbola_follows_the_travel_time_equation():
    eps, d, x0 = 9.0, 0.3, 0.5
    s = point_targets_bscan([[x0, d]], eps_r=eps, offset_m=0.0, direct_wave=0.0, n_traces=101,
                            dt_s=0.02e-9, n_samples=1000, t0_s=1e-9)
    v = velocity_from_eps_r(eps)
    for i in (20, 50, 90):
        x = i * 0.01
        t = 1e-9 + 2 * np.hypot(x - x0, d) / v
        k = np.argmax(s.data[i])
        assert k * s.dt_s == pytest.approx(t, abs=s.dt_s)
    assert s.metadata["truth"][0]["apex_time_s"] == pytest.approx(1e-9 + 2 * d / v, rel=1e-9, abs=0)
