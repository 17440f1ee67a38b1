import numpy as np
import pytest

from gpr3d.core.deps import require
from gpr3d.core.errors import MissingDependencyError
from gpr3d.core.poses import quat_from_yaw, rotate_vectors, slerp, yaw_from_quat
from gpr3d.core.units import C0, depth_to_twt, eps_r_from_velocity, twt_to_depth, velocity_from_eps_r


def test_rotation_matches_rotation_matrix():
    yaw = 0.7
    q = quat_from_yaw(yaw)[0]
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    v = np.array([0.3, -1.2, 2.0])
    np.testing.assert_allclose(rotate_vectors(q, v), R @ v, atol=1e-12)
    assert yaw_from_quat(q) == pytest.approx(yaw)


def test_slerp_halfway_and_shortest_arc():
    q0, q1 = quat_from_yaw([0.0]), quat_from_yaw([1.0])
    assert yaw_from_quat(slerp(q0, q1, [0.5]))[0] == pytest.approx(0.5)
    assert yaw_from_quat(slerp(q0, -q1, [0.5]))[0] == pytest.approx(0.5)  # -q is the same rotation


def test_units_round_trip():
    assert velocity_from_eps_r(9.0) == pytest.approx(C0 / 3)
    assert eps_r_from_velocity(C0 / 3) == pytest.approx(9.0)
    d = np.array([0.1, 0.5, 2.0])
    np.testing.assert_allclose(twt_to_depth(depth_to_twt(d, 6.0, 0.3), 6.0, 0.3), d)
    with pytest.raises(ValueError):
        velocity_from_eps_r(0.5)


def test_missing_dependency_hint(monkeypatch):
    from gpr3d.core import deps

    monkeypatch.setitem(deps.EXTRAS, "definitely_not_a_module_xyz", ("dl", "testing"))
    with pytest.raises(MissingDependencyError, match=r"pip install 'gpr3d\[dl\]'") as info:
        require("definitely_not_a_module_xyz")
    assert "needed for testing" in str(info.value)
