import math

import numpy as np
import pytest

from gpr3d.core.units import C0
from gpr3d.simulation.sampler import RANGES, sample_scene
from gpr3d.simulation.scene import Scene


def test_json_round_trip():
    s = sample_scene(3, 17)
    back = Scene.from_json(s.to_json())
    assert back.to_json() == s.to_json()
    assert back.to_dict()["derived"]["dx_m"] == s.dx


def test_reproducible_from_seed_and_index():
    assert sample_scene(5, 9).to_json() == sample_scene(5, 9).to_json()
    assert sample_scene(5, 9).to_json() != sample_scene(5, 10).to_json()
    assert sample_scene(5, 9).to_json() != sample_scene(6, 9).to_json()


def test_ranges_hold_over_many_scenes():
    hosts = set()
    for i in range(300):
        s = sample_scene(0, i)
        r = RANGES[s.medium.kind]
        hosts.add(s.medium.kind)
        assert r["frequency_hz"][0] - 1e6 <= s.antenna.frequency_hz <= r["frequency_hz"][1] + 1e6
        assert r["eps_r"][0] <= s.medium.eps_r <= r["eps_r"][1]
        assert 1 <= len(s.targets) <= 6
        lam = s.medium.velocity_m_s / s.antenna.frequency_hz
        for t in s.targets:
            assert t.kind in r["kinds"]
            lo, hi = r["radius_m"][t.kind]
            assert lo <= t.radius_m <= hi + 1e-4
            assert t.depth_m > 0 and t.depth_m + 2 * t.radius_m < s.depth_m
            assert s.x_start_m < t.x_m < s.x_start_m + (s.n_traces - 1) * s.trace_step_m
        for a in s.targets:
            for b in s.targets:
                if a is not b:
                    gap = math.hypot(a.x_m - b.x_m, a.centre_depth_m - b.centre_depth_m)
                    assert gap > 1.5 * (a.radius_m + b.radius_m) + 0.6 * lam - 1e-3
    assert hosts == {"concrete", "soil"}


def test_grid_and_time_rules():
    s = sample_scene(0, 2)
    eps = min(s.max_eps_r(), max(1.5 * s.medium.eps_r, 20))
    lam_min = C0 / (2 * s.antenna.frequency_hz * math.sqrt(eps))
    assert lam_min / 10 - 1e-4 <= s.dx <= lam_min / 10
    assert s.time_window == pytest.approx(2 * s.depth_m / s.medium.velocity_m_s
                                          + 2 * math.sqrt(2) / s.antenna.frequency_hz, rel=1e-9, abs=0)
    x = s.trace_midpoints_x()
    assert x.size == s.n_traces and np.allclose(np.diff(x), s.trace_step_m)


def test_stones_stay_out_of_targets():
    for i in range(300):
        s = sample_scene(0, i)
        for st in s.stones:
            for t in s.targets:
                assert math.hypot(st.x_m - t.x_m, st.depth_m + st.radius_m - t.centre_depth_m) > st.radius_m + t.radius_m
