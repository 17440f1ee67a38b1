import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import InvalidDataError
from gpr3d.simulation.synthetic import ricker

DT = 0.05e-9
C0 = 299792458.0


def sloping_survey(eps_r=9.0, z_reflector=-1.0):
    """Traces along x over ground that rises 0.3 m; a flat reflector at elevation ``z_reflector``: each trace's echo
    comes 2 (z - z_reflector) / v after time zero (exact, independent of the code under test)."""
    n = 31
    x = np.linspace(0, 3, n)
    z = 0.1 * x  # 0 .. 0.3 m
    v = C0 / np.sqrt(eps_r)
    t = np.arange(600) * DT
    t0 = 2e-9
    data = np.stack([ricker(t - t0 - 2 * (zi - z_reflector) / v, 1e9) for zi in z]).astype(np.float32)
    return Survey(data=data, dt_s=DT, t0_s=t0, positions_xyz=np.c_[x, np.zeros(n), z], eps_r=eps_r), v


def test_a_flat_reflector_under_sloping_ground_comes_out_flat():
    s, v = sloping_survey()
    peaks_before = np.argmax(s.data, axis=1) * DT
    assert np.ptp(peaks_before) == pytest.approx(2 * 0.3 / v, abs=DT)  # 0.3 m of relief: the echo moves
    out = s.apply("topo_correct")
    # every echo now at the time of the highest trace's: 2 (z_max - z_reflector) / v after time zero
    peaks = np.argmax(out.data, axis=1) * DT
    assert np.ptp(peaks) <= 1.01 * DT
    assert peaks[-1] == pytest.approx(2e-9 + 2 * 1.3 / v, abs=DT)
    assert out.n_samples == s.n_samples + int(np.ceil(2 * 0.3 / v / DT - 1e-9))
    res = out.history[-1]["result"]
    assert res["datum_elevation_m"] == pytest.approx(0.3, rel=1e-9, abs=0)
    assert res["max_delay_s"] == pytest.approx(2 * 0.3 / v, rel=1e-9, abs=0)
    # the highest trace is untouched
    np.testing.assert_allclose(out.data[-1, : s.n_samples], s.data[-1], atol=1e-6)


def test_topo_correct_needs_elevations_and_a_speed():
    s, _ = sloping_survey()
    with pytest.raises(InvalidDataError, match="needs trace positions"):
        s.replace(positions_xyz=None).apply("topo_correct")
    with pytest.raises(InvalidDataError, match="give eps_r or velocity_m_s"):
        s.replace(eps_r=None).apply("topo_correct")
    with pytest.raises(InvalidDataError, match="topo_correct: eps_r must be >= 1"):
        s.apply("topo_correct", eps_r=0.5)
    with pytest.raises(InvalidDataError, match="are the elevations in metres"):
        s.replace(positions_xyz=s.positions_xyz * [1, 1, 1000]).apply("topo_correct")
