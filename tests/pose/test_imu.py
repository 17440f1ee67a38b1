"""The IMU helpers by hand: the skew matrix, SO(3) exp/log against Rodrigues' formula, the noise figures."""

import math

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.imu import GRAVITY, ImuNoise, skew, so3_exp, so3_log


def test_skew_is_the_cross_product_matrix():
    v, w = np.array([1.5, -2.0, 0.25]), np.array([-0.5, 3.0, 4.0])
    S = skew(v)
    assert S.tolist() == [[0.0, -0.25, -2.0], [0.25, 0.0, -1.5], [2.0, 1.5, 0.0]]
    np.testing.assert_allclose(S @ w, np.cross(v, w), rtol=1e-15, atol=0)
    assert skew([1, 2, 3]).dtype == np.float64


def _rodrigues(r):
    th = np.linalg.norm(r)
    if th == 0:
        return np.eye(3)
    k = r / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


@pytest.mark.parametrize("r", [[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2], [0.3, -0.2, 0.9], [1e-9, 0, 0],
                               [2.0, 1.0, -0.5]])
def test_so3_exp_is_rodrigues_and_log_inverts_it(r):
    r = np.asarray(r)
    R = so3_exp(r)
    np.testing.assert_allclose(R, _rodrigues(r), rtol=0, atol=1e-14)
    np.testing.assert_allclose(so3_log(R), r, rtol=0, atol=1e-12)
    assert so3_exp([0, 0, math.pi / 2]) @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0], abs=1e-15)  # +90 about z


def test_imu_noise_defaults_are_the_datasheet_figures_and_bad_ones_are_named():
    n = ImuNoise()
    assert GRAVITY == 9.80665
    assert n.accel_noise == pytest.approx(150e-6 * 9.80665, rel=1e-15, abs=0)
    assert n.gyro_noise == pytest.approx(0.014 * math.pi / 180, rel=1e-15, abs=0)
    assert (n.accel_bias_walk, n.gyro_bias_walk) == (3e-4, 2e-5)
    for name in ("accel_noise", "gyro_noise", "accel_bias_walk", "gyro_bias_walk"):
        for bad in (0.0, -1.0, float("nan"), float("inf")):
            with pytest.raises(InvalidDataError) as err:
                ImuNoise(**{name: bad})
            assert str(err.value) == f"IMU {name.replace('_', ' ')} must be a positive number, got {bad!r}"
    assert ImuNoise(gyro_bias_walk=1e-9).gyro_bias_walk == 1e-9
